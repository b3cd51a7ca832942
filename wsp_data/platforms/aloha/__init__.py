"""The ALOHA platform (two ViperX 300s arms, gym-aloha 0.1.5's MJCF on plain MuJoCo, rendered through OSMesa).

`env` (the scene and the joint-target replayer), `runtime` (the asset folder and the CPU GL backend, set before
MuJoCo is imported), `experts` (task registry and the scripted end-effector experts, recorded as joint
targets). Importing this package imports no simulator; the modules above do.
"""
