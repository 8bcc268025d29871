"""The output-error Levenberg-Marquardt of the closed-loop refit (``ilic_cli.diagnosis.refit.output_error_gauss_newton``)."""

from __future__ import annotations

import numpy as np

from ilic_cli.diagnosis.refit import output_error_gauss_newton

T = np.linspace(0.0, 2.0, 400)
TRUE = np.array([3.0, 1.5, 0.8, 7.0])


def _output(z: np.ndarray) -> np.ndarray:
    """A response nonlinear in two of its parameters: a decay and a sine (amplitude, frequency)."""
    return z[0] * np.exp(-z[1] * T) + z[2] * np.sin(z[3] * T)


def test_it_recovers_the_parameters_of_a_nonlinear_output() -> None:
    y = _output(TRUE)
    fit = output_error_gauss_newton(lambda z: y - _output(z), TRUE * np.array([1.2, 0.8, 1.25, 0.95]), max_iter=30, tol=1e-12)
    np.testing.assert_allclose(fit.z, TRUE, rtol=1e-6)
    assert all(b < a for a, b in zip(fit.history, fit.history[1:], strict=False))  # every step taken lowers the error
    assert fit.history[-1] < 1e-6 * fit.history[0]
    # the sensitivity is d(output)/dz at the last Jacobian: compare with the analytic one there
    assert fit.sensitivity.shape == (len(T), 4)
    assert np.linalg.norm(fit.sensitivity[:, 0] - np.exp(-fit.z[1] * T)) < 0.05 * np.linalg.norm(np.exp(-fit.z[1] * T))
    assert fit.replays >= 1 + 4 * (len(fit.history) - 1)


def test_a_start_that_does_not_simulate_is_returned_as_an_infinite_error() -> None:
    fit = output_error_gauss_newton(lambda z: None, TRUE)
    assert fit.history == [np.inf] and np.array_equal(fit.z, TRUE) and fit.replays == 1


def test_a_step_into_a_region_that_does_not_simulate_is_damped_not_taken() -> None:
    """Amplitudes above 2.5 do not simulate (the truth is 3.0): the steps towards it are damped and stay below."""
    y = _output(TRUE)
    calls: list[float] = []

    def residual(z: np.ndarray) -> np.ndarray | None:
        calls.append(float(z[0]))
        return None if z[0] > 2.5 else y - _output(z)

    start = TRUE * np.array([0.8, 1.0, 1.0, 1.0])
    fit = output_error_gauss_newton(residual, start, max_iter=30, tol=1e-12)
    assert any(c > 2.5 for c in calls)  # a step was tried there
    assert 2.4 < fit.z[0] <= 2.5 and np.isfinite(fit.history[-1]) and fit.history[-1] < fit.history[0]


def test_a_fit_predicted_to_gain_less_than_asked_stops_after_its_first_jacobian() -> None:
    """A start whose error is mostly what no parameter explains: its first step is predicted to gain less than half, so none is tried."""
    y = _output(TRUE)
    start = TRUE * np.array([1.01, 1.0, 1.0, 1.0])
    y_noisy = y + 0.05 * np.sin(37.0 * T)  # a residual no parameter explains: the 1 % start error is a small share of it
    fit = output_error_gauss_newton(lambda z: y_noisy - _output(z), start, first_gain=0.5)
    assert fit.history == [float(np.linalg.norm(y_noisy - _output(start)))] and fit.replays == 1 + 4
    assert np.array_equal(fit.z, start) and "predicted" in fit.stop
    ran = output_error_gauss_newton(lambda z: y_noisy - _output(z), start)
    assert len(ran.history) > 1 and ran.history[-1] < ran.history[0]


def _delay_refit(optimum_s: float, law_optimum: float | None = None):  # type: ignore[no-untyped-def]
    """``_output_error_refit`` of one linear parameter (optimum 2.0) and a delay (optimum ``optimum_s``), from 1.0 and -1 ms;
    with ``law_optimum``, an extra value too (a friction law's ``vc``: from 1.0, bounds 0.5 to 2)."""
    from ilic_cli.diagnosis.oe_fit import ExtraValue
    from ilic_cli.diagnosis.refit import _output_error_refit
    from ilic_cli.diagnosis.select import Step
    from ilic_cli.effects import EFFECTS

    grids = {"delay": np.linspace(-0.003, 0.003, 13)}  # 0.5 ms steps: the closed loop searches -3 ms to 1 ms around -1 ms
    extra = [] if law_optimum is None else [ExtraValue("coulomb_smoothing", "vc", "m/s", 1.0, (0.5, 2.0))]

    def residual_of(steps: list, theta: np.ndarray, values: tuple[float, ...]) -> np.ndarray:
        law = [] if law_optimum is None else [values[0] - law_optimum]
        return np.array([theta[0] - 2.0, 1e3 * (steps[0].value - optimum_s), 0.01, *law])

    start = residual_of([Step(EFFECTS["delay"], -0.001)], np.array([1.0]), (1.0,))
    error = 100.0 * float(np.linalg.norm(start))
    return _output_error_refit([], [Step(EFFECTS["delay"], -0.001)], ("a",), np.array([1.0]), grids, residual_of, error, 1.0, extra=extra)


def test_the_refit_by_output_error_keeps_an_optimum_inside_its_search_range() -> None:
    from ilic_cli.diagnosis.refit import OE_METHOD, Refit

    refit = _delay_refit(-0.0015)
    assert isinstance(refit, Refit) and refit.accepted and refit.method == OE_METHOD
    assert abs(refit.steps[0].value + 0.0015) < 1e-6 and refit.theta is not None and abs(refit.theta[0] - 2.0) < 1e-4
    (search,) = refit.searches
    assert search.effect == "delay" and search.inverse == -0.001 and search.bounds == (-0.003, 0.001) and search.std is not None


def test_the_refit_by_output_error_refuses_an_optimum_on_the_edge_of_its_search_range() -> None:
    refit = _delay_refit(-0.0029)
    assert isinstance(refit, str) and "ends with delay" in refit and "lower end of the range searched" in refit, refit


def test_an_extra_value_is_fitted_with_the_effects_and_refused_beyond_its_bounds() -> None:
    """An extra value (:class:`~ilic_cli.diagnosis.oe_fit.ExtraValue`, the friction law's ``vc`` of
    :mod:`ilic_cli.diagnosis.law_refit`) is fitted at once with the linear parameters and the effects' values, reported as a
    search of its own (not an effect's primary value), and a fit that ends outside its bounds is refused."""
    from ilic_cli.diagnosis.refit import Refit

    refit = _delay_refit(-0.0015, law_optimum=1.6)
    assert isinstance(refit, Refit) and refit.accepted and abs(refit.steps[0].value + 0.0015) < 1e-6
    law = refit.searches[-1]
    assert (law.effect, law.parameter, law.primary) == ("coulomb_smoothing", "vc", False) and abs(law.value - 1.6) < 1e-4, law
    assert "coulomb_smoothing" not in refit.value_std and law.bounds == (0.5, 2.0)
    beyond = _delay_refit(-0.0015, law_optimum=2.4)
    assert isinstance(beyond, str) and "ends with vc = " in beyond and "outside the range searched (0.5 to 2)" in beyond, beyond
