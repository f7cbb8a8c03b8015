"""Training beyond one machine on an existing engine: Ray RLlib. See
:mod:`.rllib_env` and ``scripts/train_rllib.py``; the ``[distributed]`` extra installs Ray."""
