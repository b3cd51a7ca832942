"""The LIBERO platform (robosuite on MuJoCo, rendered through OSMesa): everything specific to it.

`env` (the environment wrapper), `runtime` (offline config and asset paths LIBERO needs before import),
`experts` (task registry and the scripted pick-and-place expert), `t3` + `checkpoints/` (T3 operator models and
behaviour-cloning policies), `primitives` (T5 primitives). Importing this package imports no simulator; the
modules above do.
"""
