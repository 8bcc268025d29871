"""Controllers of the closed loop: CTC (paper eqs. 11-16, 25, 31) and the EMPS benchmark PD.

Both are evaluated once per control period by the integrator (``closed_loop``);
these dataclasses hold their settings and pack them for it.

CTC, at sample k (period ``T``)::

    qd_hat = (q(k) - q(k-1)) / T                               (eq. 25; velocity="backward")
    w      = Kp*(q_r - q) + Kv*(qd_r - qd_hat) + qdd_r         (eq. 13)
    tau    = M_hat*w + Fv_hat*qd_r + Fc_hat*(2/pi)*atan(alpha*qd_r) [+ offset_hat]   (eqs. 16, 31)
    Kp = omega^2, Kv = 2*xi*omega                              (eq. 15)

``velocity="exact"`` uses the plant's own velocity at ``t_k`` instead of eq. 25:
not a realisable controller, a reference for the bias that eq. 25 causes
(eq. 27; paper section V-B).

For the ``asymmetric`` model the Coulomb/viscous columns use the same
``(2/pi)*atan`` in place of ``sign`` (``P = (1+s)/2``, ``N = (1-s)/2``).
The force is applied from ``t_k`` to ``t_k + T`` (zero-order hold).

PD (``../shared/reference/emps-benchmark.md``), at sample k::

    qfm(k) = 0.5*qm(k) + 0.5*qm(k-1)              (velocity="averaged", the benchmark's; "backward": qfm(k) = qm(k))
    qdm(k) = (qfm(k) - qfm(k-1)) / T              ("exact": the plant's own velocity at t_k)
    v(k)   = kv*(kp*(qg(k) - qm(k)) - qdm(k))
    vir(k) = sat(v(k-1), +-vmax) + pulses(k)      (one-sample delay, then saturation)
    force  = gtau*vir(k)

``delay_samples`` (default 1, the documented loop above) is the computation
delay in control periods. Below 1 the command is computed from the same
sample's position and acts from ``t_k + delay_samples*T`` on (the plant's drive
lag carries the fraction): ``vir(k) = sat(v(k), +-vmax) + pulses(k)``, logged at
sample ``k`` as the EMPS recordings log it (their ``vir(k)`` follows the law on
``qm(k)``, not ``qm(k-1)``: :mod:`ilic_cli.simulation.timing`).

``velocity="backward"`` differences the measured position itself, the textbook discrete PD; ``"exact"`` feeds back the
plant's own velocity at the sample, as a simulator written with the state at hand may (no rig measures it so). A loop
written either way records a command the benchmark's law does not fit, and :mod:`ilic_cli.simulation.timing` reads which
estimate the recording follows, as it reads the sample.

``pulse_input="held"`` (default) holds ``vir(k)`` over the period, as the rig
did (the recorded ``vir`` includes the pulses); ``"ramp"`` moves the pulse part
linearly from ``pulses(k)`` to ``pulses(k+1)`` over the period, as the published
benchmark simulation fed them (a Simulink From Workspace input, interpolated
in continuous time); ``vir(k)`` is logged either way.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ilic_cli import parameters
from ilic_cli.errors import ParameterError
from ilic_cli.runlog import PD_VELOCITIES  # packed as the index in that tuple

# packed controller vector (read by the integrator)
C_KIND, C_KP, C_KV, C_ALPHA, C_PD_KP, C_PD_KV, C_GTAU, C_VMAX, C_ASYM, C_EXACT_VEL, C_PULSE_RAMP, C_PD_SAME, C_PD_VELOCITY, C_PD_CONTINUOUS = range(14)
N_CTRL = 14
PULSE_INPUTS = ("held", "ramp")
VELOCITY_ESTIMATES = ("backward", "exact")
KIND_CTC, KIND_PD = 0.0, 1.0

CHI_LAYOUT: tuple[str, ...] = tuple(parameters.PARAMETERS)
"""Layout of the CTC parameter vector the integrator reads: every parameter of :mod:`ilic_cli.parameters`
(M, Fv, Fc, offset, Fv_pos, Fc_pos, Fv_neg, Fc_neg; every structure maps onto it)."""


@dataclass
class CTCSettings:
    """Computed torque control (paper section IV) with online IDIM-ILIC (section V).

    Attributes
    ----------
    omega : float
        Closed-loop natural frequency (rad/s); paper: 20 Hz.
    xi : float
        Damping; paper: sqrt(2)/2.
    alpha : float
        Coulomb smoothing ``(2/pi)*atan(alpha*qd_r)``; paper: 1000.
    model : str
        Controller/identification model (``rigid``, ``rigid-offset``, ``asymmetric``).
    chi0 : dict
        Initial parameters (eq. 28: all zero except the mass, paper M0 = 100 kg).
    ilic : bool
        Update the parameters online every ``window_s``.
    window_s, sigma_max_pct, cutoff_hz : float
        IDIM-ILIC window T_obs, %sigma_max (15) and low-pass cut-off (5 Hz).
    velocity : str
        ``backward``: backward difference of the measured position (eq. 25,
        the paper's); ``exact``: the plant's velocity (studies the eq. 27 bias).
    """

    omega: float = 2.0 * math.pi * 20.0
    xi: float = math.sqrt(2.0) / 2.0
    alpha: float = 1000.0
    model: str = "rigid"
    chi0: dict[str, float] | None = None
    ilic: bool = True
    window_s: float = 6.2
    sigma_max_pct: float = 15.0
    cutoff_hz: float = 5.0
    velocity: str = "backward"

    kind = "ctc"

    @property
    def Kp(self) -> float:
        return self.omega**2

    @property
    def Kv(self) -> float:
        return 2.0 * self.xi * self.omega

    def validate(self) -> None:
        _positive(self, ("omega", "xi", "alpha", "window_s", "sigma_max_pct", "cutoff_hz"))
        if self.velocity not in VELOCITY_ESTIMATES:
            raise ParameterError("velocity", self.velocity, f"one of {', '.join(VELOCITY_ESTIMATES)}")
        names = parameters.structure_names(self.model)
        for k in self.initial():
            if k not in names:
                raise ParameterError(f"chi0.{k}", self.initial()[k], f"a parameter of the '{self.model}' structure ({', '.join(names)})")

    def initial(self) -> dict[str, float]:
        names = parameters.STRUCTURES.get(self.model, ("M",))
        chi = {n: 0.0 for n in names}
        chi["M"] = 100.0
        chi.update(self.chi0 or {})
        return chi

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["chi0"] = self.initial()
        return {"kind": "ctc", **d, "Kp": self.Kp, "Kv": self.Kv}

    def vector(self) -> np.ndarray:
        c = np.zeros(N_CTRL)
        c[C_KIND], c[C_KP], c[C_KV], c[C_ALPHA] = KIND_CTC, self.Kp, self.Kv, self.alpha
        c[C_ASYM] = 1.0 if self.model == "asymmetric" else 0.0
        c[C_EXACT_VEL] = 1.0 if self.velocity == "exact" else 0.0
        c[C_VMAX] = np.inf
        return c


@dataclass
class PDSettings:
    """The benchmark PD loop (values of DATA_EMPS.mat by default); ``pulse_input``: ``held`` or ``ramp``;
    ``delay_samples``: computation delay in periods, in [0, 1]; ``velocity``: one of :data:`PD_VELOCITIES` (module docstring)."""

    kp: float = 160.18
    kv: float = 243.45
    gtau: float = 35.15065188
    vmax: float = 10.0
    pulse_input: str = "held"
    delay_samples: float = 1.0
    velocity: str = "averaged"
    continuous: bool = False
    """The law inside the dynamics: evaluated on the plant's state at every integration step, the reference interpolated
    linearly over the period (a simulator's ODE right-hand side); logged at the samples. Its velocity is the plant's own
    (``"exact"``) and it acts at once (``delay_samples`` 0)."""

    kind = "pd"

    def validate(self) -> None:
        _positive(self, ("kp", "kv", "gtau", "vmax"))
        if self.pulse_input not in PULSE_INPUTS:
            raise ParameterError("pulse_input", self.pulse_input, f"one of {', '.join(PULSE_INPUTS)}")
        if not (math.isfinite(self.delay_samples) and 0.0 <= self.delay_samples <= 1.0):
            raise ParameterError("delay_samples", self.delay_samples, "a number of control periods in [0, 1]")
        if self.velocity not in PD_VELOCITIES:
            raise ParameterError("velocity", self.velocity, f"one of {', '.join(PD_VELOCITIES)}")
        if self.continuous and (self.velocity != "exact" or self.delay_samples != 0.0 or self.pulse_input != "held"):
            raise ParameterError("continuous", self.continuous, "a law on the plant's state (velocity exact), acting at once (delay_samples 0), pulses held")

    @property
    def same_sample(self) -> bool:
        """The command acts within the period of the position it is computed from (``delay_samples`` < 1)."""
        return self.delay_samples < 1.0

    def to_dict(self) -> dict[str, Any]:
        d, out = self.delay_samples, asdict(self)
        if self.velocity == "averaged":  # the benchmark's loop: its metadata as before the estimate was a setting
            del out["velocity"]
        if not self.continuous:  # a discrete loop (every loop before the law inside the dynamics): its metadata as before
            del out["continuous"]
        return {"kind": "pd", **out, "delay_samples": 1 if d == 1.0 else d, "position_filter": {"averaged": [0.5, 0.5], "backward": [1.0]}.get(self.velocity)}

    def vector(self) -> np.ndarray:
        c = np.zeros(N_CTRL)
        c[C_KIND], c[C_PD_KP], c[C_PD_KV], c[C_GTAU], c[C_VMAX] = KIND_PD, self.kp, self.kv, self.gtau, self.vmax
        c[C_PULSE_RAMP] = 1.0 if self.pulse_input == "ramp" else 0.0
        c[C_PD_SAME] = 1.0 if self.same_sample else 0.0
        c[C_PD_VELOCITY] = float(PD_VELOCITIES.index(self.velocity))
        c[C_PD_CONTINUOUS] = 1.0 if self.continuous else 0.0
        return c


@dataclass
class OpenLoopSettings(PDSettings):
    """No feedback: the drive applies ``gtau`` times the recorded command (the benchmark PD loop with zero gains).

    The nonlinear system identification benchmark's EMPS task simulates this
    way: the recorded ``vir`` in, the position out (:func:`plant.replay.simulate_open_loop`).
    """

    kp: float = 0.0
    kv: float = 0.0

    kind = "open-loop"

    def validate(self) -> None:
        _positive(self, ("gtau",))
        if self.kp != 0.0 or self.kv != 0.0:
            raise ParameterError("kp", self.kp, "0 (with kv = 0) in open loop")

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "open-loop", "gtau": self.gtau}


def _positive(settings: object, names: tuple[str, ...]) -> None:
    """Each named setting must be a finite number > 0."""
    for name in names:
        v = getattr(settings, name)
        if not (math.isfinite(v) and v > 0):
            raise ParameterError(name, v, "a positive number")


def chi_vector(names: tuple[str, ...], values: np.ndarray | dict[str, float]) -> np.ndarray:
    """Map model-ordered parameters onto :data:`CHI_LAYOUT` (missing -> 0)."""
    if isinstance(values, dict):
        d = {k: float(v) for k, v in values.items()}
    else:
        d = {n: float(v) for n, v in zip(names, values, strict=True)}
    return np.array([d.get(n, 0.0) for n in CHI_LAYOUT])
