"""Gearbox and driver kernel of the backward vehicle model (docs/algorithms.md §6).

The rules, units and validation are in :mod:`estimation.plants.vehicle`; this module only loops.
"""

import numba as nb
import numpy as np


@nb.njit(cache=True)
def engine_demand(wheel_torque: float, ratio: float, eta: float) -> float:
    """``T_d = T_w/(i·η)`` driving, ``T_w·η/i`` on overrun (N·m)."""
    if wheel_torque >= 0.0:
        return wheel_torque / (ratio * eta)
    return wheel_torque * eta / ratio


@nb.njit(cache=True)
def gearbox_kernel(
    v_ms: np.ndarray,
    a_ms2: np.ndarray,
    wheel_torque_nm: np.ndarray,
    dt: float,
    rpm_per_ms: np.ndarray,
    ratios: np.ndarray,
    eta: float,
    fl_speed: np.ndarray,
    fl_torque: np.ndarray,
    n_idle: float,
    n_rated: float,
    n_up_light: float,
    n_up_full: float,
    n_down: float,
    hysteresis: float,
    reserve: float,
    min_gear_time: float,
    v_stop: float,
    a_engage: float,
    slew: float,
    out_gear: np.ndarray,
    out_speed_rpm: np.ndarray,
) -> None:
    """Sequential gear choice and slew-limited engine speed (rules in
    :mod:`estimation.plants.vehicle`, step 3).

    Writes ``out_gear[k]`` (0 = neutral) and ``out_speed_rpm[k]``.
    """
    n_gears = ratios.shape[0]
    gear = 0
    since = min_gear_time
    n_e = n_idle
    step = slew * dt
    for k in range(v_ms.shape[0]):
        v = v_ms[k]
        a = a_ms2[k]
        tw = wheel_torque_nm[k]
        new = gear
        if v < v_stop:
            new = 0
        elif gear == 0 and a >= 0.0:
            best = 0  # highest gear with speed and torque margin
            for g in range(n_gears, 0, -1):
                n_g = v * rpm_per_ms[g - 1]
                td = engine_demand(tw, ratios[g - 1], eta)
                if n_g >= n_down + hysteresis and td <= reserve * np.interp(
                    n_g, fl_speed, fl_torque
                ):
                    best = g
                    break
            if a > a_engage:
                new = max(best, 1)  # pulling away: 1st with clutch slip if nothing fits
            elif best > 0:
                new = best  # rolling steadily (e.g. a trace that starts in motion)
        else:
            n_cur = v * rpm_per_ms[gear - 1]
            td = engine_demand(tw, ratios[gear - 1], eta)
            t_max = np.interp(n_cur, fl_speed, fl_torque)
            if n_cur > n_rated and gear < n_gears:
                new = gear + 1  # forced: over-speed
            elif n_cur < n_idle and a <= 0.0:
                new = 0  # forced: would stall, declutch
            elif since >= min_gear_time:
                load = min(max(td / t_max, 0.0), 1.0)
                n_up = n_up_light + (n_up_full - n_up_light) * load
                if gear < n_gears and n_cur > n_up and a >= 0.0:
                    n_next = v * rpm_per_ms[gear]
                    td_next = engine_demand(tw, ratios[gear], eta)
                    if n_next >= n_down + hysteresis and td_next <= reserve * np.interp(
                        n_next, fl_speed, fl_torque
                    ):
                        new = gear + 1
                elif gear > 1 and (n_cur < n_down or td > t_max):
                    if a < 0.0 and gear == 2:
                        new = 0  # braking towards a stop: declutch rather than engage 1st
                    elif v * rpm_per_ms[gear - 2] <= n_up_full:
                        new = gear - 1
        if new != gear:
            gear = new
            since = 0.0
        else:
            since += dt
        target = n_idle if gear == 0 else v * rpm_per_ms[gear - 1]
        target = min(max(target, n_idle), n_rated)
        if k == 0:
            n_e = target
        else:
            n_e += min(max(target - n_e, -step), step)
        out_gear[k] = gear
        out_speed_rpm[k] = n_e
