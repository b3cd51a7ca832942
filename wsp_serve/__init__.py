"""The model side of WorldSimProbe: what a world model needs to be run by `wsp generate`, in the model's own
environment. It imports numpy, msgpack and websockets and nothing of WorldSimProbe, so it can be copied or
installed beside any torch, JAX or CUDA stack (docs/guides/model-server.md).

- `wsp_serve.callables`: the two callables `wsp generate` runs (per-episode and batched, `Request`, `batched`),
  found by "module:callable".
- `wsp_serve.protocol`: the messages between `wsp generate --model ws://HOST:PORT` and a model server, and their
  msgpack-numpy codec (openpi's conventions), shared by both ends.
- `wsp_serve.server`: `wsp-serve module:callable --port P` (or `python -m wsp_serve …`) serves such a callable.
"""

from wsp_serve.callables import Request, batched

__all__ = ["Request", "batched"]
