"""The ManiSkill 3 platform (SAPIEN, CPU rendering through lavapipe): everything specific to it.

`env` (the environment wrapper), `runtime` (process settings SAPIEN needs), `experts` + `skills` (task registry
and scripted experts), `operators` (T3 operator models H1–H5), `policies` + `checkpoints/` (T3 behaviour-cloning
policies), `primitives` (T5 primitives), `teleop` (the browser teleoperation tool). Importing this package
imports no simulator; the modules above do.
"""
