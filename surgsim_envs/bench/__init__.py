"""Benchmarks: virtual material tests, analytic references, speed against accuracy, stability maps.
The model and resolution choice they feed is :func:`surgsim_envs.tissue.resolution.choose`."""
