"""A research world model behind `wsp generate`'s batched call (README, "Score a model in three commands"):
    wsp generate --model docs.example_adapter:model --release worldsimprobe --out my-submission"""
import numpy as np


class ToyNet:  # stands in for your network: here, it holds the first frame still
    def rollout(self, first_frames: np.ndarray, actions: list, seeds: list) -> list:
        return [np.repeat(f[None], len(a), axis=0) for f, a in zip(first_frames, actions)]


class Adapter:
    wsp_batch_size = 8  # `wsp generate` sends up to 8 requests of one config per call

    def __init__(self):
        self.net = ToyNet()  # load your checkpoint here (from disk: nothing downloads at run time)

    def __call__(self, requests):  # each: .first_frame (H, W, 3) uint8, .actions (T, D), .fps, .seed
        frames = self.net.rollout(np.stack([r.first_frame for r in requests]),
                                  [r.actions for r in requests], [r.seed for r in requests])
        return [np.clip(f, 0, 255).astype(np.uint8) for f in frames]  # (T, H, W, 3) each, in order


model = Adapter()
