"""Surgery planning (Vandewalle et al. 2003): soft-tissue prediction after a planned bone displacement.

- :mod:`.maxillofacial`: a synthetic maxillofacial-like case (soft-tissue layer over bone, a
  segment moved by distraction), basic vs growth model, skin surfaces for validation.
- :mod:`.sweep`: the parameter sweep of the paper's Fig. 5 (error mu, sigma against nu and k).
- :mod:`.validation_report`: the paper's validation figures (colour-coded signed distances,
  histograms with mu and sigma) for any predicted vs reference surface (``surgsim validate``).
- ``surgsim grow`` (:mod:`surgsim_envs.cli.grow`) runs the maxillofacial case from the command line.

Layer: above tissue and geometry, below scene (imports neither MuJoCo nor Gymnasium);
bench and the CLI use it.
"""
