"""Learnable filter parameters: which noise entries a fit may change.

The noise values (:class:`~fkn_bench.models.noise.NoiseParameters`) and their names and units
(:class:`~fkn_bench.models.noise.NoiseLayout`) belong to the models (:mod:`fkn_bench.models.noise`).
:class:`ParameterSet` declares which entries are learnable (diagonal standard deviations, full
Cholesky factors) and maps an unconstrained vector ``(..., size)`` through a positivity map
(``log``: ``s = exp(u)``, or ``softplus``) to :class:`NoiseParameters`; it converts to and from a
plain, JSON-compatible dict with units.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import torch
import torch.nn.functional as functional
from torch import Tensor

from fkn_bench.config_values import accepts, describe_kind
from fkn_bench.linalg import symmetrize
from fkn_bench.models.noise import NoiseLayout, NoiseParameters

__all__ = [
    "ParameterSet",
    "Positivity",
    "LEARNABLE_ENTRIES",
]

Positivity = Literal["log", "softplus"]

LEARNABLE_ENTRIES: tuple[str, ...] = ("q_std", "r_std", "p0_std", "q_chol", "r_chol")
"""Names a :class:`ParameterSet` can learn: diagonal standard deviations of ``Q``, ``R`` and
``P0``, or full lower-triangular Cholesky factors of ``Q`` or ``R``."""


def _inverse_positivity(value: Tensor, positivity: Positivity) -> Tensor:
    if positivity == "log":
        return value.log()
    # softplus^-1(y) = y + log(-expm1(-y)), stable for large y
    return value + torch.log(-torch.expm1(-value))


def _positive(raw: Tensor, positivity: Positivity) -> Tensor:
    return raw.exp() if positivity == "log" else functional.softplus(raw)


@dataclass(frozen=True)
class _Entry:
    name: str
    size: int
    dim: int


@dataclass
class ParameterSet:
    """Which noise parameters are learnable, and the map from an unconstrained vector to them.

    Args:
        layout: the variant's :class:`NoiseLayout`.
        learn: entries to learn, from :data:`LEARNABLE_ENTRIES` (default: the paper's 20 diagonal
            standard deviations ``("q_std", "r_std")``). ``q_chol`` replaces ``q_std`` (and
            ``r_chol`` replaces ``r_std``) by a full lower-triangular Cholesky factor whose
            diagonal goes through the positivity map.
        positivity: ``"log"`` (``std = exp(u)``, default) or ``"softplus"``.
        fixed: standard deviations of the entries that are not learned (default: the layout's
            defaults), as ``{"q_std": [...], "r_std": [...], "p0_std": [...]}``.
    """

    layout: NoiseLayout
    learn: tuple[str, ...] = ("q_std", "r_std")
    positivity: Positivity = "log"
    fixed: Mapping[str, Sequence[float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.learn = tuple(self.learn)
        unknown = [e for e in self.learn if e not in LEARNABLE_ENTRIES]
        if unknown:
            raise ValueError(f"unknown learnable entries {unknown}; valid: {list(LEARNABLE_ENTRIES)}")
        if len(set(self.learn)) != len(self.learn):
            raise ValueError(f"learnable entries repeated: {list(self.learn)}")
        for a, b in (("q_std", "q_chol"), ("r_std", "r_chol")):
            if a in self.learn and b in self.learn:
                raise ValueError(f"learn either '{a}' or '{b}', not both")
        if self.positivity not in ("log", "softplus"):
            raise ValueError(f"positivity must be 'log' or 'softplus' (got {self.positivity!r})")
        fixed = {}
        for name in ("q_std", "r_std", "p0_std"):
            given = self.fixed.get(name, self.layout.default(name))
            if isinstance(given, (str, bytes)) or any(isinstance(v, (bool, np.bool_, str, bytes)) for v in given):
                raise ValueError(f"fixed '{name}' must be numbers, not booleans or strings (got {list(given)!r})")
            values = tuple(float(v) for v in given)
            if len(values) != len(self.layout.default(name)):
                raise ValueError(f"fixed '{name}' needs {len(self.layout.default(name))} values (got {len(values)})")
            if not all(math.isfinite(v) and v > 0 for v in values):
                raise ValueError(f"fixed '{name}' must be finite and > 0 (got {values})")
            fixed[name] = values
        self.fixed = fixed
        self._entries = []
        for name in self.learn:
            dim = len(self.layout.default(name))
            size = dim * (dim + 1) // 2 if name.endswith("_chol") else dim
            self._entries.append(_Entry(name, size, dim))

    # ------------------------------------------------------------------ sizes and names
    @property
    def size(self) -> int:
        """Number of unconstrained values (the paper's default: 20)."""
        return sum(e.size for e in self._entries)

    def names(self) -> list[str]:
        """One name per unconstrained value, e.g. ``sigma_Q_qw`` or ``L_R_rx_qw``."""
        out: list[str] = []
        for e in self._entries:
            labels = self.layout.labels(e.name)
            tag = e.name.split("_")[0].upper()
            if e.name.endswith("_std"):
                out += [f"sigma_{tag}_{label}" for label in labels]
            else:
                rows, cols = torch.tril_indices(e.dim, e.dim).tolist()
                out += [f"L_{tag}_{labels[i]}_{labels[j]}" for i, j in zip(rows, cols)]
        return out

    # ------------------------------------------------------------------ maps
    def _cholesky(self, raw: Tensor, dim: int) -> Tensor:
        rows, cols = torch.tril_indices(dim, dim, device=raw.device)
        diagonal = rows == cols
        values = torch.where(diagonal, _positive(raw, self.positivity), raw)
        factor = raw.new_zeros(*raw.shape[:-1], dim, dim)
        factor[..., rows, cols] = values
        return factor

    def to_noise(self, raw: Tensor) -> NoiseParameters:
        """Map unconstrained values ``(..., size)`` to :class:`NoiseParameters` (same leading axes)."""
        if raw.shape[-1] != self.size:
            raise ValueError(f"expected {self.size} unconstrained values in the last axis (got {raw.shape[-1]})")
        lead = raw.shape[:-1]
        matrices: dict[str, Tensor] = {}
        offset = 0
        for e in self._entries:
            chunk = raw[..., offset : offset + e.size]
            offset += e.size
            if e.name.endswith("_std"):
                std = _positive(chunk, self.positivity)
                matrices[e.name[:-4]] = torch.diag_embed(std * std)
            else:
                factor = self._cholesky(chunk, e.dim)
                # L L^T is symmetric only to rounding on some CPUs / BLAS builds: symmetrise
                matrices[e.name[:-5]] = symmetrize(factor @ factor.transpose(-1, -2))
        for name in ("q", "r", "p0"):
            if name not in matrices:
                std = raw.new_tensor(self.fixed[f"{name}_std"])
                matrices[name] = torch.diag_embed(std * std).expand(*lead, len(std), len(std))
        return NoiseParameters(matrices["q"], matrices["r"], matrices["p0"])

    def initial_values(self, dtype: torch.dtype = torch.float64, **std: Sequence[float]) -> Tensor:
        """Unconstrained vector ``(size,)`` for given standard deviations (default: ``fixed``);
        a Cholesky entry starts diagonal."""
        parts = []
        for e in self._entries:
            key = e.name[:-5] + "_std" if e.name.endswith("_chol") else e.name
            values = torch.as_tensor(std.get(key, self.fixed[key]), dtype=dtype)
            u = _inverse_positivity(values, self.positivity)
            if e.name.endswith("_std"):
                parts.append(u)
            else:
                rows, cols = torch.tril_indices(e.dim, e.dim)
                parts.append(torch.where(rows == cols, u[rows], torch.zeros((), dtype=dtype)))
        return torch.cat(parts) if parts else torch.zeros(0, dtype=dtype)

    # ------------------------------------------------------------------ plain dicts
    def to_dict(self, raw: Tensor) -> dict[str, Any]:
        """JSON-compatible description of the values of ``raw (size,)``: per entry the labels,
        units and standard deviations (or the Cholesky factor rows)."""
        raw = raw.detach().to(torch.float64).reshape(-1)
        if raw.numel() != self.size:
            raise ValueError(f"expected {self.size} values (got {raw.numel()})")
        out: dict[str, Any] = {"positivity": self.positivity, "learned": list(self.learn), "entries": {}}
        offset = 0
        for e in self._entries:
            chunk = raw[offset : offset + e.size]
            offset += e.size
            entry: dict[str, Any] = {"labels": list(self.layout.labels(e.name)), "units": list(self.layout.units(e.name))}
            if e.name.endswith("_std"):
                entry["std"] = _positive(chunk, self.positivity).tolist()
            else:
                entry["cholesky"] = self._cholesky(chunk, e.dim).tolist()
            out["entries"][e.name] = entry
        out["fixed"] = {k: list(v) for k, v in self.fixed.items() if k not in self.learn}
        return out

    def from_dict(self, data: Mapping[str, Any], dtype: torch.dtype = torch.float64) -> Tensor:
        """Unconstrained vector for a dict written by :meth:`to_dict` (labels, and units where
        the dict records them, are checked; values must be finite numbers, never booleans or
        numeric strings: :mod:`fkn_bench.config_values`)."""
        entries = data.get("entries", {})
        parts = []
        for e in self._entries:
            if e.name not in entries:
                raise ValueError(f"parameter dict has no entry '{e.name}' (has {sorted(entries)})")
            entry = entries[e.name]
            if list(entry.get("labels", [])) != list(self.layout.labels(e.name)):
                raise ValueError(f"entry '{e.name}' labels {entry.get('labels')} do not match {list(self.layout.labels(e.name))}")
            if "units" in entry and list(entry["units"]) != list(self.layout.units(e.name)):
                raise ValueError(f"entry '{e.name}' units {entry['units']} do not match {list(self.layout.units(e.name))}")
            key, kind = ("std", list[float]) if e.name.endswith("_std") else ("cholesky", list[list[float]])
            if not accepts(kind, entry.get(key)):
                raise ValueError(f"entry '{e.name}': '{key}' must be {describe_kind(kind)}, not booleans or strings "
                                 f"(got {entry.get(key)!r})")
            if e.name.endswith("_std"):
                values = torch.as_tensor(entry["std"], dtype=dtype)
                if values.shape != (e.dim,) or not bool(torch.all((values > 0) & torch.isfinite(values))):
                    raise ValueError(f"entry '{e.name}' needs {e.dim} positive finite standard deviations")
                parts.append(_inverse_positivity(values, self.positivity))
            else:
                factor = torch.as_tensor(entry["cholesky"], dtype=dtype)
                if factor.shape != (e.dim, e.dim) or not bool(torch.isfinite(factor).all()):
                    raise ValueError(f"entry '{e.name}' needs a {e.dim}x{e.dim} finite Cholesky factor (got shape {tuple(factor.shape)})")
                rows, cols = torch.tril_indices(e.dim, e.dim)
                lower = factor[rows, cols]
                if not bool(torch.all(factor.diagonal() > 0)):
                    raise ValueError(f"entry '{e.name}' needs a positive Cholesky diagonal")
                parts.append(torch.where(rows == cols, _inverse_positivity(lower.clamp_min(1e-300), self.positivity), lower))
        return torch.cat(parts) if parts else torch.zeros(0, dtype=dtype)
