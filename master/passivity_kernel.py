"""NVIDIA Warp kernel of the master's passivity layer: the TDPA observer and the
adaptive conductance at the handle's port for every lane in one launch, after the node's own
kernel (:mod:`haptic.master.node_kernels`) wrote the command.

It computes exactly what :class:`haptic.common.model.passivity.PassivityPort` does on the master
(``receive``, ``yield_command``, ``observe``), which stays the numpy reference:
tests/master/test_passivity_kernel.py runs both on the same inputs. The kernel exists because
the port's numpy calls cost several times the node's own step (bench/loop_bench.py measures
the node stage). The port's arrays are numpy views of this kernel's buffers.
"""

from __future__ import annotations

import warp as wp

wp.config.log_level = wp.LOG_WARNING


@wp.struct
class PassivityLimits:
    """The master's passivity settings, the period and the limits it must respect (SI)."""

    period_s: wp.float64
    force_limit_N: wp.float64
    force_floor_N: wp.float64
    conductance_max_m_per_N_s: wp.float64
    correction_speed_max_m_per_s: wp.float64
    correction_accel_max_m_per_s2: wp.float64
    credit_max_J: wp.float64
    keep_J: wp.float64
    workspace_min_x_m: wp.float64
    workspace_min_y_m: wp.float64
    workspace_max_x_m: wp.float64
    workspace_max_y_m: wp.float64
    drift_rate_per_s: wp.float64
    drift_speed_max_m_per_s: wp.float64


@wp.func
def capped(tank: wp.float64, forgotten: wp.array(dtype=wp.float64), lane: int,
           credit_max: wp.float64) -> wp.float64:
    """The account after forgetting what it holds beyond ``credit_max`` (counted)."""
    excess = wp.max(tank - credit_max, wp.float64(0.0))
    forgotten[lane] = forgotten[lane] + excess
    return tank - excess


@wp.kernel
def master_passivity_kernel(
    inputs: wp.array2d(dtype=wp.float64),
    peer_value: wp.array(dtype=wp.float64),
    peer_target: wp.array2d(dtype=wp.float64),
    enabled: wp.array(dtype=wp.bool),
    faulted: wp.array(dtype=wp.bool),
    command: wp.array2d(dtype=wp.float64),
    last_command: wp.array2d(dtype=wp.float64),
    origin: wp.array2d(dtype=wp.float64),
    previous: wp.array2d(dtype=wp.float64),
    tank: wp.array(dtype=wp.float64),
    sent: wp.array(dtype=wp.float64),
    peer_sent: wp.array(dtype=wp.float64),
    input_energy: wp.array(dtype=wp.float64),
    output_energy: wp.array(dtype=wp.float64),
    forgotten: wp.array(dtype=wp.float64),
    dissipated: wp.array(dtype=wp.float64),
    correction: wp.array(dtype=wp.float64),
    active_steps: wp.array(dtype=wp.int64),
    active: wp.array(dtype=wp.bool),
    limits: PassivityLimits,
):
    """One period of one lane: receive, yield, observe (common/model/passivity.py); a lane
    switched off only notes the peer's energy and where the command is."""
    lane = wp.tid()
    zero = wp.float64(0.0)
    ts = limits.period_s
    account = tank[lane]
    # receive: the newest (largest) cumulative energy the slave handed over
    value = peer_value[lane]
    if wp.isfinite(value) and value > peer_sent[lane]:
        if active[lane]:
            account = capped(account + value - peer_sent[lane], forgotten, lane,
                             limits.credit_max_J)
        peer_sent[lane] = value
    if not active[lane]:  # switched off (paper mode, the governor's standby)
        correction[lane] = zero
        previous[lane, 0] = command[lane, 0]
        previous[lane, 1] = command[lane, 1]
        return
    # the operator's force as the node used it (non-finite: 0, saturated)
    limit = limits.force_limit_N
    fx = inputs[lane, 0]
    fy = inputs[lane, 1]
    if not wp.isfinite(fx):
        fx = zero
    if not wp.isfinite(fy):
        fy = zero
    fx = wp.clamp(fx, -limit, limit)
    fy = wp.clamp(fy, -limit, limit)
    # yield: the conductance's correction along fh by what the account lacks
    cx = command[lane, 0]
    cy = command[lane, 1]
    px = previous[lane, 0]
    py = previous[lane, 1]
    work_out = -(fx * (cx - px) + fy * (cy - py))
    excess = wp.max(work_out - account, zero)
    force2 = fx * fx + fy * fy
    norm = wp.sqrt(wp.max(force2, wp.float64(1e-300)))
    size = zero
    if force2 >= limits.force_floor_N * limits.force_floor_N:
        size = excess / norm
    size = wp.min(size, limits.conductance_max_m_per_N_s * wp.sqrt(force2) * ts)
    size = wp.min(size, wp.min(limits.correction_speed_max_m_per_s * ts,
                               correction[lane] + limits.correction_accel_max_m_per_s2 * ts * ts))
    correction[lane] = size
    if size > zero:
        active_steps[lane] = active_steps[lane] + wp.int64(1)
    dissipated[lane] = dissipated[lane] + size * wp.sqrt(force2)
    dx = size * fx / norm
    dy = size * fy / norm
    if faulted[lane]:
        dx = zero
        dy = zero
    # drift: the command towards the tool's position in handle coordinates (Ah1^-1 yt_recv),
    # slowly; its work fh . d is the operator's input where positive, else paid from what the
    # account holds after this step's other work
    tx = peer_target[lane, 0]
    ty = peer_target[lane, 1]
    if (limits.drift_rate_per_s > zero and enabled[lane] and not faulted[lane]
            and wp.isfinite(tx) and wp.isfinite(ty)):
        rate = limits.drift_rate_per_s * ts
        gx = (tx - (cx + dx)) * rate
        gy = (ty - (cy + dy)) * rate
        step = wp.sqrt(gx * gx + gy * gy)
        most = limits.drift_speed_max_m_per_s * ts
        if step > most:
            gx = gx * most / step
            gy = gy * most / step
        drift_work = fx * gx + fy * gy
        if drift_work < zero:
            budget = wp.max(account + fx * (cx + dx - px) + fy * (cy + dy - py), zero)
            if -drift_work > budget:
                gx = gx * budget / (-drift_work)
                gy = gy * budget / (-drift_work)
        dx = dx + gx
        dy = dy + gy
    mx = wp.clamp(cx + dx, limits.workspace_min_x_m, limits.workspace_max_x_m)
    my = wp.clamp(cy + dy, limits.workspace_min_y_m, limits.workspace_max_y_m)
    command[lane, 0] = mx
    command[lane, 1] = my
    origin[lane, 0] = origin[lane, 0] + (mx - last_command[lane, 0])
    origin[lane, 1] = origin[lane, 1] + (my - last_command[lane, 1])
    last_command[lane, 0] = mx
    last_command[lane, 1] = my
    # observe: the step's work fh . dcmd, and hand own input beyond keep_J to the slave
    work = fx * (mx - px) + fy * (my - py)
    input_energy[lane] = input_energy[lane] + wp.max(work, zero)
    output_energy[lane] = output_energy[lane] + wp.max(-work, zero)
    account = account + work
    give = wp.clamp(account - limits.keep_J, zero, wp.max(work, zero))
    sent[lane] = sent[lane] + give
    tank[lane] = capped(account - give, forgotten, lane, limits.credit_max_J)
    previous[lane, 0] = mx
    previous[lane, 1] = my
