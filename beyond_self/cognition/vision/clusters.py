"""Learned discretisation: continuous measurements -> the network's values, by clusters.

As in the article, the robot explores, clusters each measurement (k-means, as many clusters as
the variable has values) and a person names the clusters; here the exploration's truth names
them (Hungarian assignment on the contingency table), as plain strings a person can edit. Per
variable: its features, a transform (`log` for quantities spread over decades), an optional
standardisation, the centres and spreads. No hand-set thresholds: boundaries fall half-way between
learned centres. The JSON file format is in README.md in this folder.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from beyond_self.cognition.variables import AFFORDANCE_VARIABLES
from beyond_self.core.errors import InputError, unknown

FORMAT = "beyond-self/vision-clusters"
VERSION = 1
DEFAULT_PATH = Path(__file__).with_name("clusters_default.json")

# Which measurements each variable is clustered on, and how.
VARIABLE_FEATURES: dict[str, tuple[tuple[str, ...], str, bool]] = {
    "Color": (("L", "a", "b"), "none", False),  # CIELAB is already perceptual: ΔE distances
    "Shape": (("circularity", "rectangularity"), "none", True),
    "Size": (("diameter_m",), "log", False),
    "ObjVel": (("object_speed",), "log", False),
    "ObjHandVel": (("relative_speed",), "log", False),
    "HandVel": (("hand_speed",), "log", False),
    "Contact": (("contact_s",), "log", False),
}
_FLOOR = 1e-3  # log transform floor (m/s, s, m): a still object measures ~0, not -inf


@dataclass
class Discretiser:
    """Nearest-centre labelling of one variable."""

    variable: str
    features: tuple[str, ...]
    transform: str
    standardize: bool
    offset: np.ndarray
    scale: np.ndarray
    centers: np.ndarray  # (k, d) in the transformed, standardised space
    spread: np.ndarray  # (k,) RMS distance of members to their centre
    names: list[str]

    def space(self, x: np.ndarray) -> np.ndarray:
        """Raw feature values (n, d) or (d,) -> the clustering space."""
        z = np.atleast_2d(np.asarray(x, dtype=np.float64))
        if z.shape[1] != len(self.features):
            raise InputError(
                f"{self.variable} takes {len(self.features)} features "
                f"({', '.join(self.features)}), got {z.shape[1]}"
            )
        if self.transform == "log":
            z = np.log(np.maximum(z, _FLOOR))
        return cast(np.ndarray, (z - self.offset) / self.scale)

    def assign(self, x: np.ndarray) -> np.ndarray:
        """Cluster index of each row."""
        z = self.space(x)
        d = ((z[:, None, :] - self.centers[None, :, :]) ** 2).sum(axis=2)
        return cast(np.ndarray, np.argmin(d, axis=1))

    def label(self, x: np.ndarray | Sequence[float] | float) -> str:
        """The value name for one measurement."""
        return self.names[int(self.assign(np.atleast_1d(np.asarray(x, float)))[0])]

    def labels(self, x: np.ndarray) -> list[str]:
        return [self.names[i] for i in self.assign(x)]

    def distribution(self, x: np.ndarray | Sequence[float] | float) -> dict[str, float]:
        """A soft assignment: Gaussian likelihood of each cluster (its own spread), normalised."""
        z = self.space(np.atleast_1d(np.asarray(x, float)))[0]
        d2 = ((z[None, :] - self.centers) ** 2).sum(axis=1)
        s2 = np.maximum(self.spread, 1e-6) ** 2
        dim = self.centers.shape[1]
        logp = -0.5 * d2 / s2 - 0.5 * dim * np.log(s2)
        p = np.exp(logp - logp.max())
        p /= p.sum()
        out = dict.fromkeys(self.names, 0.0)
        for name, v in zip(self.names, p, strict=True):
            out[name] += float(v)
        return out

    def to_json(self) -> dict[str, Any]:
        return {
            "features": list(self.features),
            "transform": self.transform,
            "standardize": self.standardize,
            "offset": self.offset.tolist(),
            "scale": self.scale.tolist(),
            "centers": self.centers.tolist(),
            "spread": self.spread.tolist(),
            "names": list(self.names),
        }

    @classmethod
    def from_json(cls, variable: str, d: Mapping[str, Any]) -> Discretiser:
        try:
            disc = cls(
                variable=variable,
                features=tuple(str(f) for f in d["features"]),
                transform=str(d["transform"]),
                standardize=bool(d["standardize"]),
                offset=np.asarray(d["offset"], dtype=np.float64),
                scale=np.asarray(d["scale"], dtype=np.float64),
                centers=np.asarray(d["centers"], dtype=np.float64),
                spread=np.asarray(d["spread"], dtype=np.float64),
                names=[str(n) for n in d["names"]],
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"clusters of {variable} are malformed: {exc}") from None
        k, dim = disc.centers.shape if disc.centers.ndim == 2 else (0, 0)
        if (
            k == 0
            or dim != len(disc.features)
            or len(disc.names) != k
            or disc.spread.shape != (k,)
            or disc.offset.shape != (dim,)
            or disc.scale.shape != (dim,)
            or disc.transform not in ("none", "log")
        ):
            raise InputError(f"clusters of {variable} have inconsistent shapes or transform")
        return disc


def learn_discretiser(
    variable: str,
    x: np.ndarray,
    truth: Sequence[str] | None,
    seed: int = 0,
    names: Sequence[str] | None = None,
    restarts: int = 10,
) -> Discretiser:
    """k-means (k = number of values of `variable`) on the exploration measurements `x` (n, d);
    clusters named after the majority ground truth (`truth`) or given `names` in centre order."""
    if variable not in VARIABLE_FEATURES:
        raise unknown("variable", variable, list(VARIABLE_FEATURES))
    features, transform, standardize = VARIABLE_FEATURES[variable]
    values = AFFORDANCE_VARIABLES[variable]
    k = len(values)
    data = np.asarray(x, dtype=np.float64).reshape(len(x), -1)
    if len(data) < 3 * k:
        raise InputError(f"{len(data)} samples are too few to learn {k} {variable} clusters")
    if not np.all(np.isfinite(data)):
        raise InputError(f"{variable} measurements hold NaN or infinite values")
    z = np.log(np.maximum(data, _FLOOR)) if transform == "log" else data
    offset = z.mean(axis=0) if standardize else np.zeros(z.shape[1])
    scale = z.std(axis=0) if standardize else np.ones(z.shape[1])
    scale = np.where(scale > 1e-12, scale, 1.0)
    zs = (z - offset) / scale
    # imported here: a service that only applies clusters never loads SciPy's clustering
    from scipy.cluster.vq import kmeans2

    rng = np.random.default_rng(seed)
    best: tuple[float, np.ndarray, np.ndarray] | None = None
    for _ in range(restarts):
        centers, assign = kmeans2(zs, k, iter=50, minit="++", rng=rng)
        if len(np.unique(assign)) < k:
            continue
        inertia = float(((zs - centers[assign]) ** 2).sum())
        if best is None or inertia < best[0] - 1e-12:
            best = (inertia, centers, assign)
    if best is None:
        raise InputError(f"k-means found fewer than {k} distinct {variable} clusters in the data")
    _, centers, assign = best
    order = np.lexsort(centers.T[::-1])  # deterministic cluster order: by first coordinate
    centers = centers[order]
    assign = np.argsort(order)[assign]
    spread = np.array(
        [np.sqrt(((zs[assign == j] - centers[j]) ** 2).sum(axis=1).mean()) for j in range(k)]
    )
    if names is not None:
        if len(names) != k:
            raise InputError(f"{variable} needs {k} names, got {len(names)}")
        cluster_names = [str(n) for n in names]
    elif truth is not None:
        cluster_names = name_by_majority(assign, list(truth), values, k)
    else:
        cluster_names = [f"{variable.lower()}{j}" for j in range(k)]
    return Discretiser(
        variable, features, transform, standardize, offset, scale, centers, spread, cluster_names
    )


def name_by_majority(
    assign: np.ndarray, truth: list[str], values: Sequence[str], k: int
) -> list[str]:
    """One value per cluster, maximising the members whose true value it is (Hungarian)."""
    table = np.zeros((k, len(values)))
    index = {v: i for i, v in enumerate(values)}
    for a, t in zip(assign, truth, strict=True):
        if t not in index:
            raise unknown("ground-truth value", t, list(values))
        table[a, index[t]] += 1
    from scipy.optimize import linear_sum_assignment  # learning only, as kmeans2

    rows, cols = linear_sum_assignment(-table)
    names = [""] * k
    for r, c in zip(rows, cols, strict=True):
        names[r] = values[c]
    return names


@dataclass
class ClusterModel:
    """All the learned discretisers, with what they were learned from."""

    variables: dict[str, Discretiser]
    camera: dict[str, float] = field(default_factory=dict)
    created_by: str = ""
    training: dict[str, Any] = field(default_factory=dict)

    def discretiser(self, variable: str) -> Discretiser:
        if variable not in self.variables:
            raise unknown("clustered variable", variable, list(self.variables))
        return self.variables[variable]

    def label(self, variable: str, measurements: Mapping[str, float]) -> str:
        """The value of `variable` for a dict of named measurements."""
        disc = self.discretiser(variable)
        try:
            x = [float(measurements[f]) for f in disc.features]
        except KeyError as exc:
            raise InputError(f"{variable} needs measurement {exc.args[0]!r}") from None
        return disc.label(np.asarray(x))

    def label_all(self, measurements: Mapping[str, float]) -> dict[str, str]:
        """Every variable whose features are all present in `measurements`."""
        out = {}
        for name, disc in self.variables.items():
            if all(f in measurements for f in disc.features):
                out[name] = disc.label(np.asarray([measurements[f] for f in disc.features]))
        return out

    def rename(self, variable: str, mapping: Mapping[str, str]) -> None:
        """A person names clusters: old name -> new name."""
        disc = self.discretiser(variable)
        for old in mapping:
            if old not in disc.names:
                raise unknown(f"{variable} cluster name", old, disc.names)
        disc.names = [mapping.get(n, n) for n in disc.names]

    def to_json(self) -> dict[str, Any]:
        from beyond_self.cognition.vision.features import FEATURE_DEFINITIONS

        used = sorted({f for d in self.variables.values() for f in d.features})
        return {
            "format": FORMAT,
            "version": VERSION,
            "created_by": self.created_by,
            "camera": self.camera,
            "feature_definitions": {f: FEATURE_DEFINITIONS[f] for f in used},
            "variables": {v: d.to_json() for v, d in self.variables.items()},
            "training": self.training,
        }

    def save(self, path: str | Path) -> Path:
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps(self.to_json(), indent=1) + "\n", encoding="utf-8")
        return p

    @classmethod
    def from_json(cls, d: Mapping[str, Any], name: str = "clusters") -> ClusterModel:
        if not isinstance(d, Mapping) or d.get("format") != FORMAT:
            raise InputError(f"{name} is not a clusters file (format must be {FORMAT!r})")
        if d.get("version") != VERSION:
            raise InputError(f"{name} has version {d.get('version')!r}; valid: {VERSION}")
        variables = d.get("variables")
        if not isinstance(variables, Mapping) or not variables:
            raise InputError(f"{name} has no variables")
        return cls(
            variables={str(v): Discretiser.from_json(str(v), c) for v, c in variables.items()},
            camera=dict(d.get("camera", {})),
            created_by=str(d.get("created_by", "")),
            training=dict(d.get("training", {})),
        )

    @classmethod
    def load(cls, path: str | Path | None = None) -> ClusterModel:
        """Load a clusters file (the shipped default when `path` is None)."""
        p = Path(path) if path is not None else DEFAULT_PATH
        if not p.is_file():
            hint = (
                "; generate it with `beyond segment --learn " + str(p) + "`" if path is None else ""
            )
            raise InputError(f"clusters file {p} does not exist{hint}")
        try:
            data = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise InputError(f"clusters file {p} is not readable JSON: {exc}") from None
        return cls.from_json(data, name=f"clusters file {p}")
