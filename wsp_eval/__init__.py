"""wsp_eval: scores generated videos against a WorldSimProbe release. Never imports a simulator."""
