"""Data policies: a multilayer perceptron stored as plain arrays in a ``.npz`` file, run in numpy.

A ``.npz`` policy is *data*: loading it runs no code (``numpy.load(allow_pickle=False)``), so a
scenario may name one without ``--allow-code``. Format ``surgsim-mlp-v1`` (every array name is
fixed; shapes in brackets; ``L`` layers, ``n_0`` observation size, ``n_L`` action size):

==================  ===========================  =================================================
key                 shape / type                 meaning
==================  ===========================  =================================================
``format``          str                          ``"surgsim-mlp-v1"``
``W0`` .. ``W{L-1}``  (n_i, n_{i+1}) float         layer weights: ``h_{i+1} = act(h_i @ W_i + b_i)``
``b0`` .. ``b{L-1}``  (n_{i+1},) float             layer biases
``activation``      str                          hidden activation: tanh | relu | elu | identity
``output_activation``  str (optional)            last layer: identity (default) | tanh
``obs_mean``        (n_0,) (optional, 0)         observation normalisation:
``obs_std``         (n_0,) (optional, 1)         ``h_0 = clip((obs - obs_mean) / obs_std, -obs_clip, obs_clip)``
``obs_clip``        scalar (optional, inf)
``action_scale``    (n_L,) (optional, 1)         ``action = clip(action_bias + action_scale * h_L,``
``action_bias``     (n_L,) (optional, 0)         ``action_low, action_high)``
``action_low``      (n_L,) (optional, -inf)
``action_high``     (n_L,) (optional, +inf)
``obs_keys``        (k,) str (optional)          dict observations: concatenate these keys (flattened)
``action_keys``     (m,) str (optional)          dict actions: split the action into these keys ...
``action_sizes``    (m,) int (optional)          ... of these sizes (size 1 gives a scalar)
``log_std``         (n_L,) (optional)            Gaussian head, state-independent (SB3 PPO): log sd of ``h_L``
``log_std_W``       (n_{L-1}, n_L) (optional)    Gaussian head, state-dependent (SB3 SAC): log sd =
``log_std_b``       (n_L,) (optional)            ``clip(h_{L-1} @ log_std_W + log_std_b, log_std_min, log_std_max)``
``log_std_min/max`` scalars (optional, -20, 2)   (``h_{L-1}`` = the input of the last layer)
``mode``            str (optional)               ``deterministic`` (default) | ``stochastic``: how the
                                                 policy acts unless the caller overrides it
``noise_scale``     scalar (optional, 1)         stochastic mode: sd = ``noise_scale * exp(log_std)``
                                                 (a temperature chosen on validation seeds)
==================  ===========================  =================================================

Stochastic actions (as SB3's Gaussian policies act when not deterministic): with a Gaussian head, ``mode = stochastic`` samples the
pre-activation output ``h_L ~ N(mean, exp(log_std)^2)`` (then the output activation, e.g. SAC's
tanh squashing, scaling and clipping, exactly as the deterministic path) from a numpy
``Generator``: :meth:`NpzPolicy.reset` ``(seed)`` reseeds it (stream ``(seed, SAMPLER_STREAM)``), so an episode's actions are
reproducible from (policy file, seed, observations). ``deterministic`` uses the mean.

Every array must be finite; std must be > 0; at most :data:`MAX_LAYERS` layers and
:data:`MAX_PARAMETERS` numbers. A stable-baselines3 MLP policy maps onto it directly
(:mod:`surgsim_envs.integrations.sb3` exports one): its ``mlp_extractor.policy_net`` + ``action_net`` layers, tanh activation, the
VecNormalize mean/std as ``obs_mean``/``obs_std`` and the action space bounds as
``action_low``/``action_high``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from surgsim_envs.errors import ConfigError
from surgsim_envs.policies.npz_members import declared_arrays, read_arrays

FORMAT = "surgsim-mlp-v1"
MAX_LAYERS = 32
MAX_PARAMETERS = 50_000_000
#: bytes the members of a policy file may declare (the parameters as float64, plus the small arrays)
MAX_FILE_BYTES = 8 * MAX_PARAMETERS + (1 << 20)
#: members a policy file may hold: W/b per layer and the optional arrays of the table above
MAX_MEMBERS = 2 * MAX_LAYERS + 32
#: members that hold text; every other member holds real numbers
TEXT_KEYS = ("format", "activation", "output_activation", "mode", "obs_keys", "action_keys")
#: largest magnitude of a weight, bias, normalisation or scaling value: trained networks stay far
#: below it, and a product of a few layers of 1e300 overflows float64 to inf
MAX_ABS_PARAMETER = 1e12
ACTIVATIONS = {
    "identity": lambda x: x,
    "tanh": np.tanh,
    "relu": lambda x: np.maximum(x, 0.0),
    "elu": lambda x: np.where(x > 0, x, np.expm1(np.minimum(x, 0.0))),
}
OUTPUT_ACTIVATIONS = ("identity", "tanh")
MODES = ("deterministic", "stochastic")
#: second word of the sampler's seed sequence: keeps it independent of an env seeded alike
SAMPLER_STREAM = 0x5EED_AC7


class NpzPolicy:
    """A numpy MLP policy (see module docstring): ``policy(obs) -> action``."""

    def __init__(self, weights, biases, activation: str = "tanh", output_activation: str = "identity",
                 obs_mean=None, obs_std=None, obs_clip: float = np.inf, action_scale=None, action_bias=None,
                 action_low=None, action_high=None, obs_keys=None, action_keys=None, action_sizes=None,
                 log_std=None, log_std_W=None, log_std_b=None, log_std_min: float = -20.0,
                 log_std_max: float = 2.0, mode: str = "deterministic", noise_scale: float = 1.0,
                 seed: int | None = 0,
                 source: str = "<npz policy>"):
        self.source = source
        if not (isinstance(weights, (list, tuple)) and isinstance(biases, (list, tuple))):
            raise self._bad("weights and biases must be lists of arrays (one per layer)")
        if not (1 <= len(weights) <= MAX_LAYERS) or len(weights) != len(biases):
            raise self._bad(f"needs 1..{MAX_LAYERS} layers with one bias each, got {len(weights)} weight and "
                            f"{len(biases)} bias arrays")
        self.weights = [self._finite(w, f"W{i}", ndim=2) for i, w in enumerate(weights)]
        self.biases = [self._finite(b, f"b{i}", ndim=1) for i, b in enumerate(biases)]
        total = sum(w.size + b.size for w, b in zip(self.weights, self.biases))
        if total > MAX_PARAMETERS:
            raise self._bad(f"{total} parameters exceed the limit of {MAX_PARAMETERS}")
        for i, (w, b) in enumerate(zip(self.weights, self.biases)):
            if b.shape[0] != w.shape[1]:
                raise self._bad(f"b{i} has {b.shape[0]} values but W{i} has {w.shape[1]} outputs")
            if i and w.shape[0] != self.weights[i - 1].shape[1]:
                raise self._bad(f"W{i} takes {w.shape[0]} inputs but layer {i - 1} gives {self.weights[i - 1].shape[1]}")
        if activation not in ACTIVATIONS:
            raise self._bad(f"activation {activation!r} unknown; choose one of {sorted(ACTIVATIONS)}")
        if output_activation not in OUTPUT_ACTIVATIONS:
            raise self._bad(f"output_activation {output_activation!r} unknown; choose one of {list(OUTPUT_ACTIVATIONS)}")
        self.activation, self.output_activation = activation, output_activation
        n_in, n_out = self.weights[0].shape[0], self.weights[-1].shape[1]
        self.obs_size, self.action_size = n_in, n_out
        self.obs_mean = self._vector(obs_mean, n_in, 0.0, "obs_mean")
        self.obs_std = self._vector(obs_std, n_in, 1.0, "obs_std")
        if np.any(self.obs_std <= 0):
            raise self._bad(f"obs_std must be > 0 everywhere, got min {self.obs_std.min()}")
        self.obs_clip = float(obs_clip)
        if not self.obs_clip > 0:  # inf allowed
            raise self._bad(f"obs_clip must be > 0 (inf for none), got {obs_clip!r}")
        self.action_scale = self._vector(action_scale, n_out, 1.0, "action_scale")
        self.action_bias = self._vector(action_bias, n_out, 0.0, "action_bias")
        self.action_low = self._vector(action_low, n_out, -np.inf, "action_low", finite=False)
        self.action_high = self._vector(action_high, n_out, np.inf, "action_high", finite=False)
        if np.any(np.isnan(self.action_low)) or np.any(np.isnan(self.action_high)) or np.any(self.action_low > self.action_high):
            raise self._bad("action_low must be <= action_high (no NaN)")
        self.obs_keys = None if obs_keys is None else [str(k) for k in np.asarray(obs_keys).reshape(-1)]
        self.action_keys = None if action_keys is None else [str(k) for k in np.asarray(action_keys).reshape(-1)]
        if self.action_keys is not None:
            sizes = [1] * len(self.action_keys) if action_sizes is None else np.asarray(action_sizes).reshape(-1)
            if len(sizes) != len(self.action_keys) or any(int(s) < 1 for s in sizes) or sum(int(s) for s in sizes) != n_out:
                raise self._bad(f"action_keys {self.action_keys} with sizes {list(sizes)} must split the {n_out} "
                                "outputs exactly")
            self.action_sizes = [int(s) for s in sizes]
        self._init_gaussian(log_std, log_std_W, log_std_b, log_std_min, log_std_max, mode)
        self.noise_scale = float(noise_scale)
        if not (np.isfinite(self.noise_scale) and self.noise_scale >= 0):
            raise self._bad(f"noise_scale={noise_scale!r} must be a finite number >= 0")
        self.reset(seed)

    def _init_gaussian(self, log_std, log_std_W, log_std_b, log_std_min, log_std_max, mode) -> None:
        n_out = self.action_size
        self.log_std = None if log_std is None else self._vector(log_std, n_out, 0.0, "log_std")
        self.log_std_W = self.log_std_b = None
        if (log_std_W is None) != (log_std_b is None):
            raise self._bad("log_std_W and log_std_b come together (a state-dependent log sd layer)")
        if log_std_W is not None:
            if self.log_std is not None:
                raise self._bad("give either log_std (constant) or log_std_W/log_std_b (state-dependent), not both")
            self.log_std_W = self._finite(log_std_W, "log_std_W", ndim=2)
            self.log_std_b = self._vector(log_std_b, n_out, 0.0, "log_std_b")
            if self.log_std_W.shape != (self.weights[-1].shape[0], n_out):
                raise self._bad(f"log_std_W must have shape {(self.weights[-1].shape[0], n_out)} (input of the last "
                                f"layer, actions), got {self.log_std_W.shape}")
        self.log_std_min, self.log_std_max = float(log_std_min), float(log_std_max)
        if not (np.isfinite(self.log_std_min) and np.isfinite(self.log_std_max) and self.log_std_min <= self.log_std_max):
            raise self._bad(f"log_std_min={log_std_min!r} must be <= log_std_max={log_std_max!r} (finite)")
        self.mode = self._check_mode(mode)

    @property
    def has_gaussian(self) -> bool:
        """True when the file holds a Gaussian head (actions can be sampled)."""
        return self.log_std is not None or self.log_std_W is not None

    def reset(self, seed: int | None = None) -> None:
        """Reseed the action sampler (stochastic mode); call at each episode start for
        reproducible episodes. ``None`` draws fresh entropy. The stream is that of the seed
        sequence ``(seed, SAMPLER_STREAM)``, not ``default_rng(seed)``: Gymnasium seeds an env's
        ``np_random`` with ``default_rng(seed)``, and the same seed for the env reset and the
        policy would make the action noise replay the env's randomisation (the inclusion position)."""
        self.rng = np.random.default_rng(None if seed is None else [int(seed), SAMPLER_STREAM])

    def with_mode(self, mode: str) -> "NpzPolicy":
        """This policy acting ``deterministic`` or ``stochastic`` (ConfigError without a Gaussian head)."""
        self.mode = self._check_mode(mode)
        return self

    def _check_mode(self, mode: str) -> str:
        if mode not in MODES:
            raise self._bad(f"mode {mode!r} unknown; choose one of {list(MODES)}")
        if mode == "stochastic" and not self.has_gaussian:
            raise self._bad("mode 'stochastic' needs a Gaussian head (log_std or log_std_W/log_std_b)")
        return mode

    # -- validation helpers -------------------------------------------------------------------
    def _bad(self, msg: str) -> ConfigError:
        return ConfigError(f"policy {self.source}: {msg} (format {FORMAT}, see surgsim_envs.policies.npz_policy)")

    def _real(self, a, name: str) -> np.ndarray:
        """``a`` as a float64 array if it holds real numbers (float or int); complex, string,
        datetime, bool and object arrays are refused, not converted."""
        try:
            raw = np.asarray(a)
        except (TypeError, ValueError):
            raise self._bad(f"{name} is not a numeric array") from None
        if raw.dtype.kind not in "fiu":
            raise self._bad(f"{name} has dtype {raw.dtype}; it must hold real numbers (float or int)")
        return raw.astype(np.float64)

    def _finite(self, a, name: str, ndim: int) -> np.ndarray:
        arr = self._real(a, name)
        if arr.ndim != ndim or 0 in arr.shape:
            raise self._bad(f"{name} must be a non-empty {ndim}-D array, got shape {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise self._bad(f"{name} holds NaN or inf")
        if np.abs(arr).max() > MAX_ABS_PARAMETER:
            raise self._bad(f"{name} holds {np.abs(arr).max():.3g}, above the limit of {MAX_ABS_PARAMETER:g} in "
                            "magnitude (the forward pass would overflow)")
        return arr

    def _vector(self, a, n: int, default: float, name: str, finite: bool = True) -> np.ndarray:
        if a is None:
            return np.full(n, default)
        arr = self._real(a, name).reshape(-1)
        if arr.size == 1:
            arr = np.full(n, float(arr[0]))
        if arr.shape != (n,):
            raise self._bad(f"{name} must have {n} values, got {arr.size}")
        if finite and not np.all(np.isfinite(arr)):
            raise self._bad(f"{name} holds NaN or inf")
        if finite and arr.size and np.abs(arr).max() > MAX_ABS_PARAMETER:
            raise self._bad(f"{name} holds {np.abs(arr).max():.3g}, above the limit of {MAX_ABS_PARAMETER:g} in "
                            "magnitude")
        return arr

    # -- evaluation ---------------------------------------------------------------------------
    def _flatten(self, obs) -> np.ndarray:
        if self.obs_keys is not None:
            if not isinstance(obs, dict):
                raise self._bad(f"expects a dict observation with keys {self.obs_keys}, got {type(obs).__name__}")
            missing = [k for k in self.obs_keys if k not in obs]
            if missing:
                raise self._bad(f"observation lacks keys {missing} (has {sorted(obs)})")
            parts = [np.asarray(obs[k], dtype=np.float64).reshape(-1) for k in self.obs_keys]
            x = np.concatenate(parts) if parts else np.zeros(0)
        else:
            try:
                x = np.asarray(obs, dtype=np.float64).reshape(-1)
            except (TypeError, ValueError):
                raise self._bad(f"observation {obs!r} is not numeric; give obs_keys for dict observations") from None
        if x.shape != (self.obs_size,):
            raise self._bad(f"expects {self.obs_size} observation values, got {x.size}")
        return x

    def forward(self, x: np.ndarray) -> np.ndarray:
        """The raw network output ``h_L`` for one flat observation (before action scaling)."""
        h = np.clip((x - self.obs_mean) / self.obs_std, -self.obs_clip, self.obs_clip)
        act = ACTIVATIONS[self.activation]
        for w, b in zip(self.weights[:-1], self.biases[:-1]):
            h = act(h @ w + b)
        mean = h @ self.weights[-1] + self.biases[-1]
        if self.mode == "stochastic":
            if self.log_std is not None:
                log_std = self.log_std
            else:
                log_std = np.clip(h @ self.log_std_W + self.log_std_b, self.log_std_min, self.log_std_max)
            mean = mean + self.noise_scale * np.exp(log_std) * self.rng.standard_normal(mean.shape)
        return np.tanh(mean) if self.output_activation == "tanh" else mean

    def _act(self, x: np.ndarray) -> np.ndarray:
        """Scaled, clipped actions (float64) for finite flat observations ``x`` (one row or a batch);
        ConfigError if the network output overflowed."""
        with np.errstate(over="ignore", invalid="ignore"):
            a = np.clip(self.action_bias + self.action_scale * self.forward(x), self.action_low, self.action_high)
        if not np.all(np.isfinite(a)):
            raise self._bad("the network output overflowed (NaN/inf action); check the weights and scaling")
        return a

    def __call__(self, obs):
        x = self._flatten(obs)
        if not np.all(np.isfinite(x)):
            raise self._bad(f"observation holds NaN or inf: {x.tolist()}")
        a = self._act(x)
        if self.action_keys is None:
            return a.astype(np.float32)
        out, i = {}, 0
        for k, s in zip(self.action_keys, self.action_sizes):
            out[k] = float(a[i]) if s == 1 else a[i:i + s].copy()
            i += s
        return out

    def act_batch(self, obs) -> np.ndarray:
        """Actions ``(k, n_L)`` float32 for ``k`` array observations ``(k, n_0)`` in one pass (policies
        without ``obs_keys``/``action_keys``): what :meth:`__call__` gives row by row, up to the last
        bits of the matrix products; stochastic mode draws one noise row per observation."""
        if self.obs_keys is not None or self.action_keys is not None:
            raise self._bad("act_batch takes array observations and gives array actions; this policy has "
                            "obs_keys/action_keys: call it per observation")
        x = np.asarray(obs, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != self.obs_size:
            raise self._bad(f"act_batch expects observations of shape (k, {self.obs_size}), got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise self._bad("an observation holds NaN or inf")
        return self._act(x).astype(np.float32)

    @property
    def batched(self) -> "BatchedPolicy":
        """This policy acting on batches (:meth:`act_batch`), with its ``reset``: what
        ``SurgSimVectorEnv.rollout`` takes."""
        return BatchedPolicy(self)

    # -- files --------------------------------------------------------------------------------
    def arrays(self) -> dict:
        """The ``.npz`` arrays of this policy."""
        d = {"format": np.array(FORMAT), "activation": np.array(self.activation),
             "output_activation": np.array(self.output_activation), "obs_mean": self.obs_mean,
             "obs_std": self.obs_std, "obs_clip": np.array(self.obs_clip), "action_scale": self.action_scale,
             "action_bias": self.action_bias, "action_low": self.action_low, "action_high": self.action_high}
        for i, (w, b) in enumerate(zip(self.weights, self.biases)):
            d[f"W{i}"], d[f"b{i}"] = w, b
        if self.obs_keys is not None:
            d["obs_keys"] = np.array(self.obs_keys)
        if self.action_keys is not None:
            d["action_keys"], d["action_sizes"] = np.array(self.action_keys), np.array(self.action_sizes)
        if self.log_std is not None:
            d["log_std"] = self.log_std
        if self.log_std_W is not None:
            d["log_std_W"], d["log_std_b"] = self.log_std_W, self.log_std_b
        if self.has_gaussian:
            d["log_std_min"], d["log_std_max"] = np.array(self.log_std_min), np.array(self.log_std_max)
        d["mode"], d["noise_scale"] = np.array(self.mode), np.array(self.noise_scale)
        return d

    def save(self, path) -> Path:
        """Write the policy to ``path`` (.npz)."""
        p = Path(path)
        np.savez(p, **self.arrays())
        return p if p.suffix == ".npz" else p.with_name(p.name + ".npz")

    @classmethod
    def load(cls, path, mode: str | None = None, seed: int | None = 0, noise_scale: float | None = None) -> "NpzPolicy":
        """Read and validate a ``.npz`` policy (no pickles: loading runs no code); ``mode`` and
        ``noise_scale`` override the file's; ``seed`` seeds the action sampler."""
        p = Path(path)
        if not p.is_file():
            raise ConfigError(f"policy file {str(p)!r} not found")
        try:
            declared_arrays(p, max_members=MAX_MEMBERS, max_bytes=MAX_FILE_BYTES, text_keys=TEXT_KEYS)
            data = read_arrays(p)
        except ConfigError as exc:
            raise ConfigError(f"policy {p}: {exc}; see surgsim_envs.policies.npz_policy") from None
        fmt = str(data.get("format", ""))
        if fmt != FORMAT:
            raise ConfigError(f"policy {p}: format {fmt!r} is not {FORMAT!r}; see surgsim_envs.policies.npz_policy")
        n = 0
        while f"W{n}" in data and n <= MAX_LAYERS:
            n += 1
        weights = [data[f"W{i}"] for i in range(n)]
        biases = [data.get(f"b{i}") for i in range(n)]
        if any(b is None for b in biases):
            raise ConfigError(f"policy {p}: every W<i> needs its b<i>")

        def opt(key, kind=None):
            v = data.get(key)
            if v is None:
                return None
            return str(v) if kind is str else v

        try:
            obs_clip = float(data["obs_clip"]) if "obs_clip" in data else np.inf
            return cls(weights, biases, activation=opt("activation", str) or "tanh",
                       output_activation=opt("output_activation", str) or "identity",
                       obs_mean=opt("obs_mean"), obs_std=opt("obs_std"), obs_clip=obs_clip,
                       action_scale=opt("action_scale"), action_bias=opt("action_bias"),
                       action_low=opt("action_low"), action_high=opt("action_high"), obs_keys=opt("obs_keys"),
                       action_keys=opt("action_keys"), action_sizes=opt("action_sizes"),
                       log_std=opt("log_std"), log_std_W=opt("log_std_W"), log_std_b=opt("log_std_b"),
                       log_std_min=float(data["log_std_min"]) if "log_std_min" in data else -20.0,
                       log_std_max=float(data["log_std_max"]) if "log_std_max" in data else 2.0,
                       mode=mode or opt("mode", str) or "deterministic",
                       noise_scale=noise_scale if noise_scale is not None else
                       (float(data["noise_scale"]) if "noise_scale" in data else 1.0), seed=seed, source=str(p))
        except (TypeError, ValueError) as exc:
            if isinstance(exc, ConfigError):
                raise
            raise ConfigError(f"policy {p}: malformed array ({exc}); see surgsim_envs.policies.npz_policy") from None


class BatchedPolicy:
    """An :class:`NpzPolicy` called on a batch of observations ``(k, n_0)`` -> actions ``(k, n_L)``
    (:meth:`NpzPolicy.act_batch`); ``reset(seed)`` reseeds it. Picklable (plain arrays), so it can be
    sent to vector env workers: ``vec.rollout(NpzPolicy.load(path).batched, steps, seed=0)``."""

    def __init__(self, policy: NpzPolicy):
        self.policy = policy

    def __call__(self, obs) -> np.ndarray:
        return self.policy.act_batch(obs)

    def reset(self, seed: int | None = None) -> None:
        self.policy.reset(seed)
