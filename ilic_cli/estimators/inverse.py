"""IDIM-LS and IDIM-ILIC behind the estimator interface (:class:`ilic_cli.estimators.base.Estimator`).

Thin adapters over the numerics of :func:`ilic_cli.idim_ls.idim_ls` and :func:`ilic_cli.idim_ilic.identify_ilic`:
the prepared log's rows (saturated drive and rest left out), the regressor of the model, and what the fit found
worth a warning.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ilic_cli.closed_loop_id import plant_of
from ilic_cli.errors import IdentificationError
from ilic_cli.estimators.base import Fit, ModelSpec
from ilic_cli.idim_ilic import ILICResult, ILICSettings, identify_ilic, tracking_error_ratio
from ilic_cli.idim_ls import IDIMLSResult, LSSettings, idim_ls
from ilic_cli.lsq import LSResult
from ilic_cli.prepare import PreparedLog
from ilic_cli.runlog import RunLog
from ilic_cli.usable import identification_hold_s, identification_speed_noise, rest_left_out

Plant = tuple[dict[str, float], dict[str, dict[str, float]]]
"""Rigid parameters and effects, as a model file holds them."""

TRACKING_LIMIT = 0.5
"""A reference whose tracking error ratio ``||q_ref - q|| / ||q - mean(q)||`` exceeds this does not
track the measured joint (a well-tuned loop is near 1e-3; another joint's reference is near 1 or above)."""


def ls_fit(name: str, method: str, r: LSResult, detail: object, plant: Plant | None, warnings: tuple[str, ...] = (), **diagnostics: object) -> Fit:
    """The :class:`Fit` of a least-squares estimate ``r`` (its covariance, its residual's RMS over its rows)."""
    b = len(r.names)
    cov = r.cov if r.cov is not None else np.diag(np.asarray(r.std, dtype=np.float64) ** 2)
    rms = float(r.error_norm) / np.sqrt(r.rows) if r.rows else float("nan")
    cov = np.asarray(cov, dtype=np.float64).reshape(b, b)
    return Fit(name, method, r.names, r.theta, cov, r.std, r.rel_std_pct, rms, r.relative_error_pct, r.rows, diagnostics, warnings, plant, detail)


@dataclass(frozen=True)
class IDIMLS:
    """IDIM-LS (paper section III): the filtered, differentiated position, the decimated rows, one least squares."""

    name: str = "ls"

    def run(self, prepared: PreparedLog, model: ModelSpec, settings: LSSettings) -> IDIMLSResult:
        """The IDIM-LS result itself (:func:`ilic_cli.idim_ls.idim_ls`) on the prepared log's usable rows."""
        log = prepared.log
        try:
            return idim_ls(
                log.t,
                log["q"],
                log["tau"],
                prepared.fs_hz,
                model.regressor(prepared.fs_hz),
                settings,
                valid=prepared.valid,
                segments=prepared.segments,
                hold_s=identification_hold_s(prepared) + model.lag_s,
                speed_noise=identification_speed_noise(prepared),
            )
        except ValueError as exc:
            raise IdentificationError(prepared.source, str(exc)) from None

    def fit(self, prepared: PreparedLog, model: ModelSpec, settings: LSSettings) -> Fit:
        res = self.run(prepared, model, settings)
        rank = () if res.result.full_rank else ("IDIM-LS: the observation matrix is rank-deficient; the trajectory does not excite every parameter",)
        plant = plant_of(res.result.names, res.result.theta, model.effects)
        return ls_fit(self.name, "IDIM-LS", res.result, res, plant, rank, condition_number=res.result.condition_number, rank=res.result.rank)


def ilic_unusable(log: RunLog, fs_hz: float, settings: ILICSettings) -> str | None:
    """Why IDIM-ILIC cannot run on ``log`` (no reference, shorter than one window, a reference that does not track), else ``None``."""
    if "q_ref" not in log:
        return "the log has no reference position (q_ref)"
    if len(log) < int(round(settings.window_s * fs_hz)):
        return f"the log ({len(log) / fs_hz:.3g} s) is shorter than one window ({settings.window_s:g} s)"
    ratio = float(tracking_error_ratio(log["q_ref"], log["q"]))
    if not ratio <= TRACKING_LIMIT:
        return (
            f"the reference does not track the measured joint (tracking error ratio {ratio:.3g}, above {TRACKING_LIMIT:g}): "
            "check that the reference is this joint's"
        )
    return None


@dataclass(frozen=True)
class IDIMILIC:
    """IDIM-ILIC (paper section V): each window of the force regressed on the noise-free reference trajectory.

    The :class:`Fit` is the last window's estimate; :attr:`Fit.detail` holds every window (:class:`~ilic_cli.idim_ilic.ILICResult`).
    """

    name: str = "ilic"

    def fit(self, prepared: PreparedLog, model: ModelSpec, settings: ILICSettings) -> Fit:
        log, fs = prepared.log, prepared.fs_hz
        reason = ilic_unusable(log, fs, settings)
        if reason is not None:
            raise IdentificationError(prepared.source, f"IDIM-ILIC cannot run: {reason}")
        try:
            res = identify_ilic(
                log.t,
                log["q_ref"],
                log["tau"],
                fs,
                model.regressor(fs),
                settings,
                qd_ref=log.channels.get("qd_ref"),
                qdd_ref=log.channels.get("qdd_ref"),
                q=log["q"],
                valid=prepared.valid,
            )
        except ValueError as exc:
            raise IdentificationError(prepared.source, str(exc)) from None
        warnings: list[str] = []
        res = _without_cut_windows(res, prepared.gap_samples, fs, warnings)
        if rest_left_out(prepared) is not None:  # the windows' masked rows: at rest too, not only a saturated drive
            why = "(saturated drive, or at rest)" if prepared.saturated is not None else "(at rest)"
            res = replace(res, windows=[replace(w, note=w.note.replace("(saturated drive)", why)) for w in res.windows])
        warnings += _window_warnings(res)
        if not res.windows:
            nan = np.full(len(res.names), np.nan)
            cov = np.full((len(nan), len(nan)), np.nan)
            return Fit(self.name, "IDIM-ILIC", res.names, nan, cov, nan, nan, float("nan"), None, 0, {"windows": 0}, tuple(warnings), ({}, {}), res)
        last = res.windows[-1]
        essential: tuple[dict[str, float], dict[str, dict[str, float]]] = (
            {n: float(v) for n, v, e in zip(last.result.names, last.result.theta, last.essential, strict=True) if e},
            {},
        )
        return ls_fit(
            self.name,
            "IDIM-ILIC",
            last.result,
            res,
            essential,
            tuple(warnings),
            windows=len(res.windows),
            k=last.k,
            essential=[bool(e) for e in last.essential],
        )


def _window_warnings(res: ILICResult) -> list[str]:
    """A window's note, and each parameter not essential in some windows."""
    out: list[str] = []
    not_essential: dict[str, list[int]] = {}
    for w in res.windows:
        if w.note and not w.note.startswith("not essential"):
            out.append(f"IDIM-ILIC window k={w.k}: {w.note}")
        elif w.note:
            for name, ok in zip(w.result.names, w.essential, strict=True):
                if not ok:
                    not_essential.setdefault(name, []).append(w.k)
    for name, ks in not_essential.items():
        out.append(
            f"IDIM-ILIC: {name} not essential (%σ > {res.settings.sigma_max_pct:g}) in {len(ks)} of {len(res.windows)} windows "
            f"(k = {ranges(ks)}); it would not be updated"
        )
    return out


def _without_cut_windows(ilic: ILICResult, gap_samples: np.ndarray, fs_hz: float, warnings: list[str]) -> ILICResult:
    """``ilic`` without the windows a gap of the time stamps cuts (their filtered rows would span it), said in ``warnings``."""
    if not len(gap_samples) or not ilic.windows:
        return ilic
    n = int(round(ilic.settings.window_s * fs_hz))
    cut = {int(i) // n for i in gap_samples if (int(i) % n) < n - 1}
    kept = [w for i, w in enumerate(ilic.windows) if i not in cut]
    dropped = [w.k for i, w in enumerate(ilic.windows) if i in cut]
    if dropped:
        warnings.append(f"IDIM-ILIC: window(s) k = {ranges(dropped)} dropped: a gap in the time stamps cuts them")
    return replace(ilic, windows=kept)


def ranges(ks: list[int]) -> str:
    """``[1, 2, 3, 5]`` -> ``"1-3, 5"``."""
    parts: list[str] = []
    start = prev = ks[0]
    for k in [*ks[1:], None]:
        if k is not None and k == prev + 1:
            prev = k
            continue
        parts.append(f"{start}" if start == prev else f"{start}-{prev}")
        if k is not None:
            start = prev = k
    return ", ".join(parts)
