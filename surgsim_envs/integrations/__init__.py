"""Glue to other libraries' formats and frameworks: dm_control and dm_env (:mod:`.dm_control`),
stable-baselines3 (:mod:`.sb3`), Ray RLlib (:mod:`.rllib`), Minari datasets
(:mod:`.minari_datasets`). Each imports its library only when used."""
