"""Platform-free tools over the platforms' action sources: `survey` (expert success per task, through the kit).
Everything specific to a simulator (experts, operators, policies, primitives, teleoperation) lives in its
platform package, `wsp_data/platforms/<name>/`."""
