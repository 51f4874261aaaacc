"""NVIDIA Warp kernel of the master's passivity layer: the TDPA observer and the
adaptive conductance at the handle's port for every lane in one launch, after the node's own
kernel (:mod:`haptic.master.node_kernels`) wrote the command.

It computes exactly what :class:`haptic.common.model.passivity.PassivityPort` does on the master
(``receive``, ``yield_command``, ``observe``), which stays the numpy reference:
tests/common/control/test_passivity_kernel.py runs both on the same inputs. The kernel exists
because the port's numpy calls cost several times the node's own step (bench/loop_bench.py measures
the node stage). The port's arrays are numpy views of this kernel's buffers.
"""

from __future__ import annotations

import warp as wp

from haptic.common.control.command_funcs import clamp_to_box, finite_or_zero, rebase_origin

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


@wp.func
def receive_stage(lane: int, account: wp.float64, peer_value: wp.array(dtype=wp.float64),
                  peer_sent: wp.array(dtype=wp.float64), active: wp.array(dtype=wp.bool),
                  forgotten: wp.array(dtype=wp.float64), credit_max: wp.float64) -> wp.float64:
    """``receive``: the account (J) credited with what the newest (largest) cumulative energy
    the slave handed over adds (where the lane is active); the peer's total is noted."""
    value = peer_value[lane]
    credited = account
    if wp.isfinite(value) and value > peer_sent[lane]:
        if active[lane]:
            credited = capped(account + value - peer_sent[lane], forgotten, lane, credit_max)
        peer_sent[lane] = value
    return credited


@wp.func
def conductance_stage(lane: int, force: wp.vec2d, moved: wp.vec2d, account: wp.float64,
                      correction: wp.array(dtype=wp.float64),
                      active_steps: wp.array(dtype=wp.int64),
                      dissipated: wp.array(dtype=wp.float64),
                      limits: PassivityLimits) -> wp.vec2d:
    """``yield_command``: the conductance's correction (m) along the operator's force (N) by
    what the account (J) lacks for this step's work on the command's move ``moved`` (m),
    within the conductance's, speed's and acceleration's limits."""
    zero = wp.float64(0.0)
    ts = limits.period_s
    fx = force[0]
    fy = force[1]
    work_out = -(fx * moved[0] + fy * moved[1])
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
    return wp.vec2d(size * fx / norm, size * fy / norm)


@wp.func
def drift_stage(force: wp.vec2d, command: wp.vec2d, previous: wp.vec2d, shift: wp.vec2d,
                target: wp.vec2d, account: wp.float64, limits: PassivityLimits) -> wp.vec2d:
    """The drift (m): the corrected command ``command + shift`` slowly towards the tool's
    position in handle coordinates ``target`` (Ah1^-1 yt_recv, m); its work on the operator's
    force (N) is the operator's input where positive, else paid from what the account (J)
    holds after this step's other work (``previous``: the command before this step)."""
    zero = wp.float64(0.0)
    fx = force[0]
    fy = force[1]
    rate = limits.drift_rate_per_s * limits.period_s
    gx = (target[0] - (command[0] + shift[0])) * rate
    gy = (target[1] - (command[1] + shift[1])) * rate
    step = wp.sqrt(gx * gx + gy * gy)
    most = limits.drift_speed_max_m_per_s * limits.period_s
    if step > most:
        gx = gx * most / step
        gy = gy * most / step
    drift_work = fx * gx + fy * gy
    if drift_work < zero:
        budget = wp.max(account + fx * (command[0] + shift[0] - previous[0])
                        + fy * (command[1] + shift[1] - previous[1]), zero)
        if -drift_work > budget:
            gx = gx * budget / (-drift_work)
            gy = gy * budget / (-drift_work)
    return wp.vec2d(gx, gy)


@wp.func
def observe_stage(lane: int, force: wp.vec2d, moved: wp.vec2d, account: wp.float64,
                  input_energy: wp.array(dtype=wp.float64),
                  output_energy: wp.array(dtype=wp.float64), sent: wp.array(dtype=wp.float64),
                  tank: wp.array(dtype=wp.float64), forgotten: wp.array(dtype=wp.float64),
                  limits: PassivityLimits):
    """``observe``: the step's work (J) of the operator's force (N) on the command's move
    ``moved`` (m) into the account; the own input beyond ``keep_J`` is handed to the slave."""
    zero = wp.float64(0.0)
    work = force[0] * moved[0] + force[1] * moved[1]
    input_energy[lane] = input_energy[lane] + wp.max(work, zero)
    output_energy[lane] = output_energy[lane] + wp.max(-work, zero)
    total = account + work
    give = wp.clamp(total - limits.keep_J, zero, wp.max(work, zero))
    sent[lane] = sent[lane] + give
    tank[lane] = capped(total - give, forgotten, lane, limits.credit_max_J)


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
    account = receive_stage(lane, tank[lane], peer_value, peer_sent, active, forgotten,
                            limits.credit_max_J)
    cmd = wp.vec2d(command[lane, 0], command[lane, 1])
    if not active[lane]:  # switched off (paper mode, the governor's standby)
        correction[lane] = wp.float64(0.0)
        previous[lane, 0] = cmd[0]
        previous[lane, 1] = cmd[1]
        return
    # the operator's force as the node used it (non-finite: 0, saturated)
    limit = limits.force_limit_N
    force = wp.vec2d(wp.clamp(finite_or_zero(inputs[lane, 0]), -limit, limit),
                     wp.clamp(finite_or_zero(inputs[lane, 1]), -limit, limit))
    before = wp.vec2d(previous[lane, 0], previous[lane, 1])
    shift = conductance_stage(lane, force, wp.vec2d(cmd[0] - before[0], cmd[1] - before[1]),
                              account, correction, active_steps, dissipated, limits)
    if faulted[lane]:
        shift = wp.vec2d(wp.float64(0.0), wp.float64(0.0))
    target = wp.vec2d(peer_target[lane, 0], peer_target[lane, 1])
    if (limits.drift_rate_per_s > wp.float64(0.0) and enabled[lane] and not faulted[lane]
            and wp.isfinite(target[0]) and wp.isfinite(target[1])):
        drift = drift_stage(force, cmd, before, shift, target, account, limits)
        shift = wp.vec2d(shift[0] + drift[0], shift[1] + drift[1])
    sent_cmd = clamp_to_box(wp.vec2d(cmd[0] + shift[0], cmd[1] + shift[1]),
                            limits.workspace_min_x_m, limits.workspace_min_y_m,
                            limits.workspace_max_x_m, limits.workspace_max_y_m)
    command[lane, 0] = sent_cmd[0]
    command[lane, 1] = sent_cmd[1]
    rebase_origin(origin, lane, sent_cmd, wp.vec2d(last_command[lane, 0], last_command[lane, 1]))
    last_command[lane, 0] = sent_cmd[0]
    last_command[lane, 1] = sent_cmd[1]
    observe_stage(lane, force, wp.vec2d(sent_cmd[0] - before[0], sent_cmd[1] - before[1]),
                  account, input_energy, output_energy, sent, tank, forgotten, limits)
    previous[lane, 0] = sent_cmd[0]
    previous[lane, 1] = sent_cmd[1]
