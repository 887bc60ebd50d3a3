"""The training tests' small run settings."""

# A shallow trunk keeps every test fast; the code paths are the full ones.
TINY = dict(batch_size=1, replay_capacity=64, checkpoint_every=2, target_update_every=2, net_config={"trunk_depth": 2}, torch_threads=1)
