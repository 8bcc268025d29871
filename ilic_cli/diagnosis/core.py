"""``ilic diagnose`` logic: compare, locate, name, model, and show the fit improve.

Takes run logs (no file I/O here) and returns a :class:`Diagnosis`; the
command module renders it (:mod:`ilic_cli.diagnosis.report`) and plots it
(:mod:`ilic_cli.diagnosis.plots`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ilic_cli.diagnosis.catalogue import FLEX_DAMPING, Effect, catalogue
from ilic_cli.diagnosis.locate import SIGNATURE_KINDS, Region, force_lag, locate
from ilic_cli.diagnosis.select import Evaluation, SelectSettings, Step, forward_select, moving_rows, system, validation_error
from ilic_cli.diagnosis.stats import blocked_folds, gls_covariance, heldout_errors
from ilic_cli.errors import IdentificationError
from ilic_cli.idim_ls import IDIMData, LSSettings, prepare
from ilic_cli.lsq import LSResult, _num, solve
from ilic_cli.regressor import MODELS, Model, get_model
from ilic_cli.runlog import RunLog


@dataclass(frozen=True)
class DiagnoseSettings:
    """Settings of a diagnosis.

    Attributes
    ----------
    model : str
        Rigid model structure identified first (``rigid-offset``).
    ls : LSSettings
        IDIM-LS filtering and decimation (benchmark defaults).
    select : SelectSettings
        Statistics of the forward selection.
    simulate : bool
        Replay the recorded reference through the plant (before/after).
    """

    model: str = "rigid-offset"
    ls: LSSettings = LSSettings()
    select: SelectSettings = SelectSettings()
    simulate: bool = True


@dataclass(frozen=True)
class Estimate:
    """A value with its standard deviation (``None`` when not estimated) and unit."""

    value: float
    std: float | None
    unit: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"value": _num(self.value), "std": None if self.std is None else _num(self.std), "unit": self.unit}


@dataclass
class Finding:
    """One effect the model left out, with its estimate and the evidence."""

    effect: Effect
    parameters: dict[str, Estimate]
    plant_effect: dict[str, float] | None
    located: list[Region]
    evidence: Evaluation
    note: str = ""

    def to_dict(self) -> dict[str, Any]:
        ev = self.evidence.to_dict()
        ev.pop("effect", None)
        return {
            "effect": self.effect.id,
            "title": self.effect.title,
            "explanation": self.effect.explanation,
            "form": self.effect.form,
            "signature": self.effect.signature,
            "parameters": {k: v.to_dict() for k, v in self.parameters.items()},
            "plant_effect": self.plant_effect,
            "located": [r.to_dict() for r in self.located],
            "evidence": ev,
            "note": self.note,
        }


@dataclass
class SimulationComparison:
    """Replay of the recorded reference compared with the recording (relative errors, %)."""

    before: dict[str, float]
    after: dict[str, float] | None
    source: str
    located: list[Region] = field(default_factory=list)
    note: str = ""
    signals: dict[str, np.ndarray] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"source": self.source, "before": self.before, "after": self.after, "located": [r.to_dict() for r in self.located], "note": self.note}


@dataclass
class Diagnosis:
    """Everything ``ilic diagnose`` found on one log."""

    source: str
    model: str
    fs_hz: float
    rows_used: int
    rows_total: int
    base: LSResult
    augmented: LSResult
    findings: list[Finding]
    fit: dict[str, dict[str, float | None]]
    located: list[Region]
    tried: list[list[Evaluation]]
    model_file: dict[str, Any]
    settings: DiagnoseSettings
    simulation: SimulationComparison | None = None
    validation_source: str | None = None
    warnings: list[str] = field(default_factory=list)
    residual: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def conclusion(self) -> str:
        if not self.findings:
            return "no significant mismatch"
        return "left out: " + ", ".join(f.effect.title for f in self.findings)

    def to_dict(self) -> dict[str, Any]:
        return {
            "source": self.source,
            "model": self.model,
            "sample_rate_hz": self.fs_hz,
            "rows_used": self.rows_used,
            "rows_total": self.rows_total,
            "conclusion": self.conclusion,
            "findings": [f.to_dict() for f in self.findings],
            "fit": self.fit,
            "base": self.base.to_dict(),
            "augmented": self.augmented.to_dict(),
            "located": [r.to_dict() for r in self.located],
            "selection": [[e.to_dict() for e in step] for step in self.tried],
            "simulation": None if self.simulation is None else self.simulation.to_dict(),
            "validation_source": self.validation_source,
            "model_file": self.model_file,
            "settings": {"model": self.settings.model, "ls": self.settings.ls.to_dict(), "selection": self.settings.select.to_dict()},
            "warnings": list(self.warnings),
        }


# ---------------------------------------------------------------------------
# parameters in the plant's vocabulary
# ---------------------------------------------------------------------------
def _lin(names: tuple[str, ...], theta: np.ndarray, cov: np.ndarray, weights: dict[str, float]) -> tuple[float, float]:
    """Value and std of a linear combination of parameters."""
    w = np.array([weights.get(n, 0.0) for n in names])
    return float(w @ theta), float(math.sqrt(max(w @ cov @ w, 0.0)))


def effect_parameters(step: Step, names: tuple[str, ...], theta: np.ndarray, cov: np.ndarray, value_std: float | None,
                      hold_s: float = 0.0) -> tuple[dict[str, Estimate], dict[str, float] | None, str]:
    """Parameters of one finding (plant names, with std), its plant effect entry, and a note.

    ``hold_s``: half a sample period when the logged force is the held drive
    command (it acts over the next period, so a rigid drive already shows a
    delay of ``-hold_s``); the plant's ``delay`` is the found one plus
    ``hold_s``, since the plant holds its force itself.
    """
    e, v = step.effect, step.value
    p: dict[str, Estimate] = {}
    idx = {n: i for i, n in enumerate(names)}
    val = lambda n: float(theta[idx[n]])  # noqa: E731
    note = ""
    if e.id == "asymmetric_friction":
        fv = _lin(names, theta, cov, {"Fv": 1.0})
        fvn = _lin(names, theta, cov, {"Fv": 1.0, "dFv_neg": 1.0})
        p["Fv_pos"], p["Fv_neg"] = Estimate(*fv, "N/(m/s)"), Estimate(*fvn, "N/(m/s)")
        fc = _lin(names, theta, cov, {"Fc": 1.0}) if "Fc" in idx else (0.0, 0.0)
        if "offset" in idx:
            p["Fc_pos"] = Estimate(*_lin(names, theta, cov, {"Fc": 1.0, "offset": 1.0}), "N")
            p["Fc_neg"] = Estimate(*_lin(names, theta, cov, {"Fc": 1.0, "offset": -1.0}), "N")
            note = "Fc_pos/Fc_neg attribute the whole constant offset to Coulomb asymmetry; the two cannot be told apart (the model file keeps Fc symmetric plus the offset)"
        plant = {"Fv_pos": fv[0], "Fv_neg": fvn[0], "Fc_pos": fc[0], "Fc_neg": fc[0]}
        return p, plant, note
    if e.id == "stribeck":
        fs = _lin(names, theta, cov, {"Fs": 1.0})
        p["Fs"], p["vs"] = Estimate(*fs, "N"), Estimate(float(v), value_std, "m/s")
        fc = min(val("Fc_pos"), val("Fc_neg")) if "Fc_pos" in idx and "Fc_neg" in idx else (val("Fc") if "Fc" in idx else 0.0)
        plant = {"Fs": fs[0], "vs": float(v)} if fc + fs[0] >= 0 else None
        if plant is None:
            note = f"Fs = {fs[0]:.3g} N would put the static friction level Fc + Fs below 0: not in the model file"
        elif fs[0] < 0:
            note = f"negative Fs, kept in the model file: the plant's static friction level Fc + Fs is {fc + fs[0]:.3g} N"
        return p, plant, note
    if e.id == "position_ripple":
        a, b = val("ripple_sin"), val("ripple_cos")
        ia, ib = idx["ripple_sin"], idx["ripple_cos"]
        A = math.hypot(a, b)
        J_A = np.array([a, b]) / A if A > 0 else np.zeros(2)
        J_ph = np.array([-b, a]) / (A * A) if A > 0 else np.zeros(2)
        C = cov[np.ix_([ia, ib], [ia, ib])]
        p["A"] = Estimate(A, float(math.sqrt(max(J_A @ C @ J_A, 0.0))), "N")
        p["L"] = Estimate(float(v), value_std, "m")
        p["phase"] = Estimate(math.atan2(b, a), float(math.sqrt(max(J_ph @ C @ J_ph, 0.0))), "rad")
        return p, {"A": A, "L": float(v), "phase": math.atan2(b, a)}, note
    if e.id == "spring":
        k = _lin(names, theta, cov, {"k_spring": 1.0})
        p["k"] = Estimate(*k, "N/m")
        note = "the rest position q0 is absorbed by the offset (q0 = 0 in the model file)" if "offset" in idx else ""
        return p, {"k": k[0], "q0": 0.0}, note
    if e.id == "payload_change":
        dm = _lin(names, theta, cov, {"dM": 1.0})
        p["dM"], p["t_change"] = Estimate(*dm, "kg"), Estimate(float(v), value_std, "s")
        return p, {"dM": dm[0], "t_change": float(v)}, note
    if e.id == "offset":
        p["offset"] = Estimate(*_lin(names, theta, cov, {"offset": 1.0}), "N")
        return p, None, note
    if e.id == "delay":
        p["delay"] = Estimate(float(v), value_std, "s")
        d = float(v) + hold_s
        if hold_s:
            note = (f"the logged force is the held command: {-hold_s * 1e3:.3g} ms of the delay is the zero-order hold, "
                    f"the plant's delay is {d * 1e3:.3g} ms")
        if d < 0:
            note += ("; " if note else "") + "negative: the force acts after it is logged (drive lag)"
        return p, {"delay": d}, note
    if e.id == "flexibility":
        f_res, zeta = (float(v), FLEX_DAMPING) if np.isscalar(v) else (float(v[0]), float(v[1]))
        ml = _lin(names, theta, cov, {"M_load": 1.0})
        M = val("M") if "M" in idx else float("nan")
        w = 2.0 * math.pi * f_res
        p["f_res"] = Estimate(f_res, value_std, "Hz")
        p["damping_ratio"] = Estimate(zeta, None, "")
        p["M_load"] = Estimate(*ml, "kg")
        frac = ml[0] / M if M > 0 else float("nan")
        p["load_fraction"] = Estimate(frac, ml[1] / M if M > 0 else None, "")
        k = w * w * ml[0]
        k_std = None
        if value_std is not None and ml[0] > 0:
            k_std = k * math.sqrt((2 * value_std / f_res) ** 2 + (ml[1] / ml[0]) ** 2)
        p["stiffness"] = Estimate(k, k_std, "N/m")
        c = 2.0 * zeta * math.sqrt(max(k * ml[0], 0.0))
        p["damping"] = Estimate(c, None, "N/(m/s)")
        plant = {"stiffness": k, "damping": c, "load_fraction": frac} if 0 < frac < 1 else None
        note = "" if plant else "the load fraction is outside (0, 1): not a plant flexibility"
        return p, plant, note
    return p, None, note


def steps_from_effects(effects: dict[str, Any], M: float, fs_hz: float) -> list[Step]:
    """Known effects of a model file as fixed steps (their nonlinear values)."""
    cat = catalogue(fs_hz)
    out = []
    for eid, prm in effects.items():
        if eid not in cat or not isinstance(prm, dict):
            continue
        e = cat[eid]
        if eid == "stribeck":
            out.append(Step(e, float(prm.get("vs", 0.01))))
        elif eid == "position_ripple":
            out.append(Step(e, float(prm.get("L", 0.01))))
        elif eid == "payload_change":
            out.append(Step(e, float(prm.get("t_change", 0.0))))
        elif eid == "delay":
            out.append(Step(e, float(prm.get("delay", 0.0))))
        elif eid == "flexibility":
            ml = float(prm.get("load_fraction", 0.3)) * M
            k = float(prm.get("stiffness", 1e6))
            zeta = float(prm.get("damping", 0.0)) / (2.0 * math.sqrt(k * ml))
            out.append(Step(e, (math.sqrt(k / ml) / (2 * math.pi), zeta)))
        elif eid in ("asymmetric_friction", "spring"):
            out.append(Step(e))
    return out


# ---------------------------------------------------------------------------
# the diagnosis
# ---------------------------------------------------------------------------
def _fs(log: RunLog) -> float:
    return 1.0 / log.dt_s


def _prepare(log: RunLog, model: Model, settings: LSSettings) -> IDIMData:
    src = log.meta.get("source")
    try:
        return prepare(log.t, log["q"], log["tau"], _fs(log), model, settings)
    except ValueError as exc:
        raise IdentificationError(src, str(exc)) from None


def base_model(model_doc: dict[str, Any] | None, default: str) -> Model:
    """The rigid structure: the model file's (by name, or by its parameter names), else ``default``."""
    if model_doc is None:
        return get_model(default)
    name = model_doc.get("model")
    if name in MODELS:
        return MODELS[name]
    params = set(model_doc["parameters"])
    for m in MODELS.values():
        if set(m.names) == params & {"M", "Fv", "Fc", "offset", "Fv_pos", "Fv_neg", "Fc_pos", "Fc_neg"}:
            return m
    return get_model(default)


def diagnose(
    log: RunLog,
    *,
    settings: DiagnoseSettings = DiagnoseSettings(),
    model_doc: dict[str, Any] | None = None,
    against: RunLog | None = None,
    validate: RunLog | None = None,
) -> Diagnosis:
    """Diagnose ``log``: what does the rigid model leave out?

    Parameters
    ----------
    log : RunLog
        The recording (``t``, ``q``, ``tau``; ``q_ref`` for the simulation comparison).
    settings : DiagnoseSettings
    model_doc : dict, optional
        A parsed model file (:func:`ilic_cli.modelfile.parse_model`): its
        structure is the starting model, its values are replayed as "before",
        and its effects are kept and not searched again.
    against : RunLog, optional
        A simulated log to compare the recording with (instead of replaying).
    validate : RunLog, optional
        Another recording: candidates must not raise the error there.
    """
    fs = _fs(log)
    src = str(log.meta.get("source", ""))
    warnings: list[str] = []
    try:
        base = base_model(model_doc, settings.model)
    except ValueError as exc:
        raise IdentificationError(None, str(exc)) from None
    data = _prepare(log, base, settings.ls)
    vdata = _prepare(validate, base, settings.ls) if validate is not None else None
    known = steps_from_effects(model_doc.get("effects", {}), float(model_doc["parameters"].get("M", 95.0)), fs) if model_doc else []
    sel_settings = settings.select
    if known:
        sel_settings = SelectSettings(**{**sel_settings.__dict__, "effects": tuple(e for e in sel_settings.effects if e not in {s.effect.id for s in known})})
    selection = forward_select(data, base, fs, sel_settings, validation=vdata, known=known)
    rows = moving_rows(data)
    steps = [*known, *selection.steps]
    W0, y0, names0 = system(data, base, known, rows)
    W1, y1, names1 = system(data, base, steps, rows)
    if not len(y0) > 4 * W1.shape[1]:
        raise IdentificationError(src, f"only {len(y0)} usable rows after leaving out standstill: too few to diagnose")
    res0 = solve(W0, y0, names0, sigma=settings.ls.sigma)
    res1 = solve(W1, y1, names1, sigma=settings.ls.sigma)
    cov1 = gls_covariance(W1, y1, res1.theta)
    res1 = _with_std(res1, cov1)
    res0 = _with_std(res0, gls_covariance(W0, y0, res0.theta))
    folds = blocked_folds(len(y0), sel_settings.folds, sel_settings.guard)
    h0 = heldout_errors(W0, y0, folds)
    h1 = heldout_errors(W1, y1, folds)
    fit: dict[str, dict[str, float | None]] = {
        "relative_error_pct": {"before": res0.relative_error_pct, "after": res1.relative_error_pct},
        "heldout_relative_error_pct": {"before": 100 * float(np.linalg.norm(h0) / np.linalg.norm(y0)), "after": 100 * float(np.linalg.norm(h1) / np.linalg.norm(y1))},
        "validation_relative_error_pct": {"before": None, "after": None},
        "simulation_force_relative_error_pct": {"before": None, "after": None},
    }
    if vdata is not None:
        fit["validation_relative_error_pct"] = {"before": validation_error(data, vdata, base, known), "after": validation_error(data, vdata, base, steps)}
    # locate on the rigid residual (decimated rows) and the force lag
    dec = data.decimate
    kin = data.kin
    td, qd_d, qdd_d, q_d = data.t_dec[rows], dec(kin.qd)[rows], dec(kin.qdd)[rows], dec(kin.q)[rows]
    e0 = y0 - W0 @ res0.theta
    e1 = y1 - W1 @ res1.theta
    fs_dec = fs / settings.ls.decimation
    alpha = sel_settings.alpha
    located = locate(e0, t=td, q=q_d, qd=qd_d, qdd=qdd_d, W=W0, fs_hz=fs_dec, alpha=alpha)
    full = np.asarray(base.matrix(kin)) @ res0.theta[: len(base.names)]
    located.append(force_lag(data.tau, full, fs))
    findings = []
    theta_by = dict(zip(names1, res1.theta, strict=True))
    from ilic_cli.diagnosis.compare import tau_sensor

    hold_s = 0.5 / fs if tau_sensor(log) == "command" else 0.0
    for st, ev in zip(selection.steps, selection.accepted, strict=True):
        params, plant, note = effect_parameters(st, names1, res1.theta, cov1, ev.value_std, hold_s)
        kinds = SIGNATURE_KINDS.get(st.effect.id, ())
        regs = sorted([r for r in located if r.kind in kinds and r.significant], key=lambda r: r.p_value)
        findings.append(Finding(st.effect, params, plant, regs, ev, note))
    rigid, effects_doc = model_parameters(base, theta_by, steps, names1, res1.theta, cov1, hold_s)
    from ilic_cli.modelfile import model_document

    doc = model_document(base.name, rigid, method="IDIM-LS + ilic diagnose", effects=effects_doc, source=src or None)
    diag = Diagnosis(
        source=src,
        model=base.name,
        fs_hz=fs,
        rows_used=int(rows.sum()),
        rows_total=len(rows),
        base=res0,
        augmented=res1,
        findings=findings,
        fit=fit,
        located=located,
        tried=selection.tried,
        model_file=doc,
        settings=settings,
        validation_source=None if validate is None else str(validate.meta.get("source", "")),
        warnings=warnings,
        residual={"t": td, "q": q_d, "qd": qd_d, "before": e0, "after": e1, "y": y0, "y_before": W0 @ res0.theta, "y_after": W1 @ res1.theta},
    )
    if settings.simulate or against is not None:
        from ilic_cli.diagnosis.compare import compare_simulation

        before_params = dict(model_doc["parameters"]) if model_doc else {n: float(v) for n, v in zip(names0, res0.theta, strict=True)}
        before_effects = dict(model_doc.get("effects", {})) if model_doc else {}
        try:
            diag.simulation = compare_simulation(log, data, rows, before_params, before_effects, doc["parameters"], doc["effects"] if findings else None, against=against, ls=settings.ls, alpha=alpha)
        except ImportError as exc:
            warnings.append(f"no simulation comparison: the plant is not available ({exc})")
        if diag.simulation is not None:
            fit["simulation_force_relative_error_pct"] = {"before": diag.simulation.before.get("force"), "after": (diag.simulation.after or {}).get("force")}
            if diag.simulation.note:
                warnings.append(diag.simulation.note)
    return diag


def _with_std(res: LSResult, cov: np.ndarray) -> LSResult:
    """``res`` with standard deviations from the autocorrelation-aware covariance."""
    from dataclasses import replace

    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(res.theta != 0, 100.0 * std / np.abs(res.theta), np.inf)
    return replace(res, std=std, rel_std_pct=rel)


def model_parameters(base: Model, theta: dict[str, float], steps: list[Step], names: tuple[str, ...], values: np.ndarray, cov: np.ndarray,
                     hold_s: float = 0.0) -> tuple[dict[str, float], dict[str, Any]]:
    """Rigid parameters and plant effects of the augmented model (for the model file; ``hold_s`` see :func:`effect_parameters`)."""
    rigid = {n: float(theta[n]) for n in ("M", "Fv", "Fc", "offset") if n in theta}
    if "offset" in theta:
        rigid["offset"] = float(theta["offset"])
    effects: dict[str, Any] = {}
    for st in steps:
        _, plant, _ = effect_parameters(st, names, values, cov, None, hold_s)
        if st.effect.id == "offset":
            continue
        if plant is not None:
            effects[st.effect.id] = {k: float(v) for k, v in plant.items()}
    return rigid, effects
