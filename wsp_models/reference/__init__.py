"""The reference world model: network, training data, training loop, and the batched `wsp generate` model."""
