"""Priors: JSON files (``priors/*.json``) to vectorised log densities.

Each parameter is sampled in an unbounded or simply bounded space: log for
positive quantities (log-normal, half-normal), identity otherwise. Densities in
the sampling space include the Jacobian, so emcee sees the right target.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import special, stats

from ..physics.effects import EFFECT_NAMES
from ..physics.lumped import kx_nd

_DISTS = {"lognormal", "normal", "truncnormal", "halfnormal", "uniform", "arcsine"}


@dataclass(frozen=True)
class ParamPrior:
    """Prior of one scalar parameter (natural units) and its sampling transform."""

    name: str
    dist: str
    args: tuple
    unit: str = ""

    @property
    def log_space(self) -> bool:
        return self.dist in ("lognormal", "halfnormal")

    def to_sample(self, x):
        return np.log(x) if self.log_space else np.asarray(x, float)

    def from_sample(self, u):
        if not self.log_space:
            return np.asarray(u, float)
        with np.errstate(over="ignore"):  # a walker far out (u > 709) is inf, where its prior has no weight
            return np.exp(u)

    def _angles(self) -> tuple[float, float]:
        """An arcsine prior's support as angles: x = sin(t) with t uniform on (asin(low), asin(high))."""
        return math.asin(self.args[0]), math.asin(self.args[1])

    def logpdf_sample(self, u) -> np.ndarray:
        """Log density of the sampling-space value u (vectorised); -inf outside the support."""
        u = np.asarray(u, float)
        a = self.args
        if self.dist == "lognormal":  # u = log x ~ N(log median, sigma)
            return -0.5 * ((u - math.log(a[0])) / a[1]) ** 2 - math.log(a[1] * math.sqrt(2 * math.pi))
        if self.dist == "halfnormal":  # x = e^u, p(u) = p(x) x
            with np.errstate(over="ignore", invalid="ignore"):  # a proposal far out (x above 1e154 N): density 0
                x = np.exp(u)
                out = math.log(2) - 0.5 * (x / a[0]) ** 2 - math.log(a[0] * math.sqrt(2 * math.pi)) + u
            return np.where(np.isinf(x), -np.inf, out)
        if self.dist == "normal":
            return -0.5 * ((u - a[0]) / a[1]) ** 2 - math.log(a[1] * math.sqrt(2 * math.pi))
        if self.dist == "truncnormal":
            mean, sd, lo, hi = a
            z = special.ndtr((hi - mean) / sd) - special.ndtr((lo - mean) / sd)
            out = -0.5 * ((u - mean) / sd) ** 2 - math.log(sd * math.sqrt(2 * math.pi) * z)
            return np.where((u >= lo) & (u <= hi), out, -np.inf)
        if self.dist == "uniform":
            lo, hi = a
            return np.where((u >= lo) & (u <= hi), -math.log(hi - lo), -np.inf)
        if self.dist == "clamp_or_uniform":  # z: a clamp on [-width, 0] (mass 1/2), u = scale z uniform on (0, u_max]
            width, scale, u_max = a
            out = np.where(u > 0, math.log(0.5 * scale / u_max), -math.log(2.0 * width))  # p(z) = p(u) du/dz
            return np.where((u >= -width) & (u <= u_max / scale), out, -np.inf)
        if self.dist == "arcsine":  # density (1 - x^2)^(-1/2) / (asin(high) - asin(low)) on [low, high]
            lo, hi = a
            inside = (u >= lo) & (u <= hi)
            t0, t1 = self._angles()
            out = -0.5 * np.log1p(-(np.where(inside, u, 0.0) ** 2)) - math.log(t1 - t0)
            return np.where(inside, out, -np.inf)
        raise AssertionError(self.dist)

    def bounds(self) -> tuple[float, float]:
        """Support in natural units."""
        if self.dist == "truncnormal":
            return self.args[2], self.args[3]
        if self.dist in ("uniform", "arcsine"):
            return self.args
        if self.dist == "clamp_or_uniform":
            return -self.args[0], self.args[2] / self.args[1]
        if self.log_space:
            return 0.0, math.inf
        return -math.inf, math.inf

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """Draws in natural units."""
        a = self.args
        if self.dist == "lognormal":
            return a[0] * np.exp(a[1] * rng.standard_normal(n))
        if self.dist == "halfnormal":
            return np.abs(a[0] * rng.standard_normal(n))
        if self.dist == "normal":
            return a[0] + a[1] * rng.standard_normal(n)
        if self.dist == "truncnormal":
            mean, sd, lo, hi = a
            return stats.truncnorm.rvs((lo - mean) / sd, (hi - mean) / sd, loc=mean, scale=sd, size=n, random_state=rng)
        if self.dist == "arcsine":  # x = sin(t), t uniform: dx = cos(t) dt = sqrt(1 - x^2) dt
            return np.sin(rng.uniform(*self._angles(), n))
        if self.dist == "clamp_or_uniform":
            return self._clamp_or_uniform_quantile(rng.uniform(0.0, 1.0, n))
        return rng.uniform(a[0], a[1], n)

    def quantile(self, q: float) -> float:
        a = self.args
        if self.dist == "lognormal":
            return float(a[0] * math.exp(a[1] * stats.norm.ppf(q)))
        if self.dist == "halfnormal":
            return float(stats.halfnorm.ppf(q, scale=a[0]))
        if self.dist == "normal":
            return float(stats.norm.ppf(q, a[0], a[1]))
        if self.dist == "truncnormal":
            mean, sd, lo, hi = a
            return float(stats.truncnorm.ppf(q, (lo - mean) / sd, (hi - mean) / sd, loc=mean, scale=sd))
        if self.dist == "arcsine":
            t0, t1 = self._angles()
            return float(math.sin(t0 + q * (t1 - t0)))
        if self.dist == "clamp_or_uniform":
            return float(self._clamp_or_uniform_quantile(np.asarray(q, float)))
        return float(a[0] + q * (a[1] - a[0]))

    def _clamp_or_uniform_quantile(self, q: NDArray) -> NDArray:
        """Inverse CDF of ``clamp_or_uniform``: the lower half of q on the clamp, the upper half uniform in u."""
        width, scale, u_max = self.args
        return np.where(q <= 0.5, width * (2.0 * q - 1.0), np.maximum(2.0 * q - 1.0, 0.0) * u_max / scale)


#: the base spring's table coordinate u at the start above which it is sampled in log k
#: (:meth:`ParameterSpace.settle_base_coordinates`)
BASE_U_SWITCH = 0.5


def _open_unit(u) -> tuple[NDArray, NDArray]:
    """Where ``u`` lies in (0, 1), and ``u`` with 0.5 elsewhere (finite logs to mask afterwards)."""
    inside = (u > 0.0) & (u < 1.0)
    return inside, np.where(inside, u, 0.5)


def log_compliance_factor(p, eta: float) -> NDArray:
    """log C(p) with C(p) = int_0^eta (eta - x)^2 (1 - x)^(-4p) dx: the small-deflection tip compliance of the
    taper law EI(s) = EI0 (1 - s/L)^(4p) at the contact height eta = h/L, in units of L^3 / EI0, i.e.
    -log of :func:`bayesrod.physics.lumped.kx_nd` (eq. kx, closed form; C(0) = eta^3 / 3, k_x = 3 EI / h^3 for a
    uniform rod). ``p`` any shape."""
    return -np.log(kx_nd(eta, np.asarray(p, float)))


class ParameterSpace:
    """Named parameters with their priors (``names``, ``priors``): maps between natural units and the
    sampling space, shared by the posteriors emcee sees.

    Each parameter is sampled through its prior's own transform (log for positive parameters), with
    one exception: an AR(1) force noise (``sigma_force_N`` with ``rho_force``, or their per-condition
    copies) is sampled as the log of its innovation sd, log(sigma sqrt(1 - rho^2)), beside rho. The
    marginal sd sigma is poorly determined as rho nears 1 while the innovation sd is not, so in
    (log sigma, rho) the posterior is a curved ridge the ensemble moves cross slowly. The map
    (log innovation sd, rho) -> (log sigma, rho) is a shear of unit Jacobian. The sd's prior is the
    innovation sd's (since session 53: :meth:`PosteriorBase.log_prior` evaluates it at the sampled
    coordinate; docs/priors.md, "The force noise's sd under AR(1)"); to_natural still returns the
    marginal sd (docs/inference.md, "Correlated force noise").

    A second exception when ``base_length_m`` is set (a single fit with ``base_compliance`` on forces
    alone, both it and EI0 with log-space priors, its start a stiff spring:
    :meth:`settle_base_coordinates`): the base spring k is sampled by its table coordinate u = c / (1 + c),
    c = EI0 / (k L), in (0, 1). Forces that see EI0 and the spring in series pin a curve along which
    log EI0 and p move with c, nearly straight in u, sharply bent in log k (an L: a stiff clamp's long,
    prior-limited arm and the soft spring's branch), which the ensembles crossed slowly: R-hat up to 1.21
    after 8000 steps, 6 of 12 forces-only SBC cases unconverged (docs/inference.md, "Sampling"). This map is not
    of unit Jacobian; :meth:`log_jacobian` holds its log determinant.

    A third when ``stiffness_at`` = (h, L) is set (every push at one height h, L known): log EI0 is
    sampled as log EI0 - log C(p), C(p) = int_0^eta (eta - x)^2 (1 - x)^(-4p) dx at eta = h / L, the log of
    the rod's small-deflection stiffness at h up to a constant (k = F / delta = EI0 / (L^3 C(p))). Forces at
    one height pin that stiffness and hardly p, so in (log EI0, p) the posterior is a ridge log EI0 = log k +
    log C(p), curved (C grows steeply with p), which the ensembles crossed slowly (a fit-group series at
    one height: R-hat 1.77 after 6000 steps); in (log k, p) it runs along p. A shear of unit Jacobian, like
    the noise's (docs/inference.md, "Sampling"). Not with a base spring (:meth:`stiffness_pair`).
    """

    names: list
    priors: list
    #: the length L [m] in the base spring's coordinate c = EI0 / (k L); None: k is sampled in log k
    base_length_m: float | None = None
    #: (h, L) [m] of a fit whose pushes are all at one contact height h on a known length L: EI0 is sampled
    #: as the log of the small-deflection stiffness there (:meth:`stiffness_pair`); None: as log EI0
    stiffness_at: tuple[float, float] | None = None

    @property
    def ndim(self) -> int:
        return len(self.names)

    def noise_pairs(self) -> list[tuple[int, int]]:
        """(sd column, correlation column) of each AR(1) force noise sampled by its innovation sd: each sd with
        the correlation of the same suffix, or, where one ``rho_force`` is shared by conditions with a sd each
        (``sigma_force_N__<c>``), every such sd with it."""
        idx = {n: i for i, n in enumerate(self.names)}
        pairs = []
        for n, i in idx.items():
            if n == "rho_force" or n.startswith("rho_force__"):
                sds = [idx.get("sigma_force_N" + n[len("rho_force") :])]
                if n == "rho_force" and sds[0] is None:
                    sds = [j for m, j in idx.items() if m.startswith("sigma_force_N__")]
                for s in sds:
                    if s is not None and self.priors[s].log_space and not self.priors[i].log_space:
                        pairs.append((s, i))
        return pairs

    def _shear(self, theta, sign: float) -> NDArray:
        """A copy of ``theta`` (..., ndim) with each noise pair's log sd moved by
        sign x log sqrt(1 - rho^2): -1 from the marginal to the innovation sd, +1 back."""
        out = np.array(theta, float, copy=True)
        for s, r in self.noise_pairs():
            rho = np.clip(out[..., r], -1.0 + 1e-12, 1.0 - 1e-12)
            out[..., s] = out[..., s] - sign * 0.5 * np.log1p(-(rho**2))
        return out

    def stiffness_pair(self) -> tuple[int, int] | None:
        """(EI0 column, p column) when EI0 is sampled as the log stiffness at one height, else None.

        None also with a base spring (``base_compliance``): in series with the spring the stiffness at the
        height is not the rod's, and the shear bent the posterior instead (spring in u: a one-push fit ended
        at R-hat 1.012 where u alone converged; in log k from a soft start: the SBC's seed 25 at 1.41 where
        log EI0 gave 1.009; docs/inference.md, "Sampling")."""
        if self.stiffness_at is None or "base_compliance" in self.names:
            return None
        if "EI0" not in self.names or "p" not in self.names:
            return None
        i, j = self.names.index("EI0"), self.names.index("p")
        return (i, j) if self.priors[i].log_space and not self.priors[j].log_space else None

    def _stiffness_shift(self, p) -> NDArray:
        """log C(p) (see the class docstring) at the taper exponents ``p`` (any shape)."""
        h, L = self.stiffness_at
        return log_compliance_factor(p, h / L)

    def base_pair(self) -> tuple[int, int] | None:
        """(EI0 column, base spring column) when the spring is sampled by its table coordinate u, else None."""
        if self.base_length_m is None or "base_compliance" not in self.names or "EI0" not in self.names:
            return None
        i, j = self.names.index("EI0"), self.names.index("base_compliance")
        return (i, j) if self.priors[i].log_space and self.priors[j].log_space else None

    def prior_coordinates(self, theta) -> NDArray:
        """``theta`` (..., ndim) in the sampling space mapped to each prior's own transform: the log of
        the marginal noise sd in place of the innovation sd (a shear of unit Jacobian), log k in place of
        the base spring's u (Jacobian :meth:`log_jacobian`; u outside (0, 1) maps to nan)."""
        out = self._shear(theta, +1.0)
        stiff = self.stiffness_pair()
        if stiff is not None:
            out[..., stiff[0]] = out[..., stiff[0]] + self._stiffness_shift(out[..., stiff[1]])
        pair = self.base_pair()
        if pair is not None:
            i, j = pair
            inside, u = _open_unit(out[..., j])
            logc = np.log(u) - np.log1p(-u)
            out[..., j] = np.where(inside, out[..., i] - math.log(self.base_length_m) - logc, np.nan)
        return out

    def settle_base_coordinates(self, theta) -> NDArray:
        """The start ``theta`` (ndim,) in the coordinates the base spring will be sampled in: u where the
        start's spring is stiff (u <= :data:`BASE_U_SWITCH`), else log k (``base_length_m`` unset).

        u straightens the stiff clamp's arm of the posterior (k free, EI0 and p moving with c) but bends
        the soft spring's (k pinned, EI0 free: log EI0 grows as -log(1 - u) up to the table's cap), where
        log k is straight: on a soft base (scripts/sbc_geometry.py seed 11, u 0.93) sampling in u left
        R-hat at 1.59-1.63 after 8000 steps against 1.007 in log k (docs/validation.md, "Sampling a base
        spring"). With centerlines the fit never sets ``base_length_m`` (log k throughout): they pin EI0
        and p apart from the spring, and a stiff clamp's prior-limited tail in k, a Gaussian tail in log k,
        is a logarithmic spike at u = 0 (R-hat 1.02-1.05 on 3 of 11 SBC cases in u, at most 1.010 in
        log k). Both are the same posterior; the rule depends only on the data and the start, so a
        resumed run makes the same choice.
        """
        pair = self.base_pair()
        theta = np.asarray(theta, float)
        if pair is None or theta[pair[1]] <= BASE_U_SWITCH:
            return theta
        natural = self.to_natural(theta[None])
        self.base_length_m = None
        return self.to_sample(natural)[0]

    def log_jacobian(self, theta) -> NDArray:
        """log |d(prior coordinates) / d(sampling coordinates)| at ``theta`` (..., ndim): 0 but for the base
        spring's u, where d log k / du = -1 / (u (1 - u)); -inf for u outside (0, 1)."""
        theta = np.asarray(theta, float)
        pair = self.base_pair()
        if pair is None:
            return np.zeros(theta.shape[:-1])
        inside, u = _open_unit(theta[..., pair[1]])
        return np.where(inside, -np.log(u) - np.log1p(-u), -np.inf)

    def to_natural(self, theta) -> dict:
        theta = self.prior_coordinates(np.atleast_2d(theta))
        return {n: pr.from_sample(theta[:, i]) for i, (n, pr) in enumerate(zip(self.names, self.priors, strict=True))}

    def to_sample(self, natural: dict) -> NDArray:
        each = [pr.to_sample(np.atleast_1d(natural[n])) for n, pr in zip(self.names, self.priors, strict=True)]
        out = self._shear(np.stack(each, axis=-1), -1.0)
        pair = self.base_pair()
        if pair is not None:
            c = np.exp(out[..., pair[0]] - out[..., pair[1]]) / self.base_length_m  # EI0 / (k L)
            out[..., pair[1]] = c / (1.0 + c)
        stiff = self.stiffness_pair()
        if stiff is not None:
            out[..., stiff[0]] = out[..., stiff[0]] - self._stiffness_shift(out[..., stiff[1]])
        return out


def _parse_param(name: str, spec: dict, source: str) -> ParamPrior:
    where = f"{source}: {name}"
    if not isinstance(spec, dict) or spec.get("dist") not in _DISTS:
        raise ValueError(
            f"{where}.dist: expected one of {', '.join(sorted(_DISTS))}, got "
            f"{spec.get('dist') if isinstance(spec, dict) else spec!r}"
        )
    d = spec["dist"]
    keys = {
        "lognormal": ("median", "sigma_log"),
        "normal": ("mean", "sd"),
        "halfnormal": ("scale",),
        "truncnormal": ("mean", "sd", "low", "high"),
        "uniform": ("low", "high"),
        "arcsine": ("low", "high"),
    }[d]
    vals = []
    for k in keys:
        v = spec.get(k)
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            raise ValueError(f"{where}.{k}: expected a finite number for a {d} prior, got {v!r}")
        vals.append(float(v))
    positive = {"lognormal": (0, 1), "normal": (1,), "halfnormal": (0,), "truncnormal": (1,)}.get(d, ())
    for i in positive:
        if vals[i] <= 0:
            raise ValueError(f"{where}.{keys[i]}: expected a value > 0, got {vals[i]}")
    if d in ("truncnormal", "uniform", "arcsine") and not vals[-2] < vals[-1]:
        raise ValueError(f"{where}: expected low < high, got {vals[-2]} and {vals[-1]}")
    if d == "arcsine" and not -1.0 < vals[0] < vals[1] < 1.0:
        raise ValueError(f"{where}: expected -1 < low < high < 1 for an arcsine prior, got {vals[0]} and {vals[1]}")
    return ParamPrior(name, d, tuple(vals), spec.get("unit", ""))


@dataclass(frozen=True)
class Prior:
    """A named prior: core parameters and effect parameters."""

    name: str
    params: dict
    effects: dict
    source: str
    doc: dict

    def get(self, name: str) -> ParamPrior:
        if name in self.params:
            return self.params[name]
        if name in self.effects:
            return self.effects[name]
        if name in NUISANCE_DEFAULTS:
            return NUISANCE_DEFAULTS[name]
        raise ValueError(f"prior {self.name}: expected a prior for {name}, got none in {self.source}")


REQUIRED = ("EI0", "p", "sigma_force_N", "sigma_shape_m", "shape_sd_scale")

#: priors of nuisance parameters a prior file may leave out (docs/priors.md): the lag-1 correlation of
#: AR(1) force noise, arcsine over [-0.5, 0.995]: density proportional to (1 - rho^2)^(-1/2), the
#: reference (Jeffreys) prior of a stationary AR(1) correlation, truncated. Under a uniform prior the
#: 90% intervals of EI0 and p covered 84% / 82% of 150 replicates at rho 0.9 (docs/validation.md).
#: Real pushes measured 0.82-0.98; the upper bound keeps the noise stationary and away from a random
#: walk, which would absorb any misfit.
NUISANCE_DEFAULTS = {"rho_force": ParamPrior("rho_force", "arcsine", (-0.5, 0.995), "1")}


def marginal_force_sd(innovation_sd: ArrayLike, rho: ArrayLike) -> NDArray:
    """The marginal sd [N] of AR(1) force noise whose innovations have sd ``innovation_sd`` [N] and whose lag-1
    correlation is ``rho``: sigma = innovation_sd / sqrt(1 - rho^2) (any broadcastable shapes).

    Under AR(1) noise the file's ``sigma_force_N`` prior is the innovation sd's (docs/priors.md): a draw from
    the prior is an innovation sd from that prior and rho from its own, mapped to sigma_force_N by this."""
    return np.asarray(innovation_sd, float) / np.sqrt(1.0 - np.asarray(rho, float) ** 2)


def _priors_dir():
    """The prior files: the installed ``bayesrod.priors`` package, or ``priors/`` of a source checkout."""
    try:
        return resources.files("bayesrod.priors")
    except ModuleNotFoundError:  # running from a source tree (e.g. pytest in a fresh clone)
        return Path(__file__).resolve().parents[2] / "priors"


def available_priors() -> list[str]:
    return sorted(p.name[:-5] for p in _priors_dir().iterdir() if p.name.endswith(".json"))


def load_prior(name_or_path: str | None = None) -> Prior:
    """Load a bundled prior by name (``default``, ``grass``, ``woody``) or a JSON file path."""
    name_or_path = name_or_path or "default"
    path = Path(name_or_path)
    if path.suffix == ".json" or path.exists():
        if not path.is_file():
            raise ValueError(
                f"prior: expected a prior name ({', '.join(available_priors())}) or a JSON file, "
                f"got {name_or_path!r} (no such file)"
            )
        text, source = path.read_text(), str(path)
    else:
        res = _priors_dir() / f"{name_or_path}.json"
        if not res.is_file():
            raise ValueError(
                f"prior: expected one of {', '.join(available_priors())} or a JSON file, got {name_or_path!r}"
            )
        text, source = res.read_text(), f"priors/{name_or_path}.json"
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{source}: expected valid JSON, got {exc.msg} at line {exc.lineno}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("parameters"), dict):
        raise ValueError(f"{source}: parameters: expected an object of parameter priors, got none")
    params = {k: _parse_param(k, v, source) for k, v in doc["parameters"].items()}
    missing = [k for k in REQUIRED if k not in params]
    if missing:
        raise ValueError(f"{source}: parameters.{missing[0]}: expected a prior, got none")
    effects = {k: _parse_param(k, v, source) for k, v in (doc.get("effects") or {}).items()}
    unknown = sorted(set(effects) - set(EFFECT_NAMES))
    if unknown:
        raise ValueError(f"{source}: effects.{unknown[0]}: expected one of {', '.join(EFFECT_NAMES)}, got it")
    return Prior(doc.get("name", path.stem), params, effects, source, doc)
