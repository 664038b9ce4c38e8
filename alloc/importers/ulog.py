"""PX4 flight logs (ULog) replayed through any allocator: PX4's demands in, our commands out,
compared with what PX4 commanded.

A ULog of PX4's ``control_allocator`` (v1.13 and later) holds the demands it allocated,
``vehicle_torque_setpoint.xyz`` and ``vehicle_thrust_setpoint.xyz`` (normalised, body axes), and
the motor commands it sent, ``actuator_motors.control`` (0..1).  :func:`read_ulog` pairs each
motor sample with the setpoints of the same ``timestamp_sample`` (the allocator publishes its
output with the sample time of the demand it allocated); :func:`replay` allocates every paired
demand with a method of the registry on the vehicle of the log's own parameters
(:func:`alloc.importers.px4.vehicle_from_params` with PX4's normalisation, so the demands are in
the effectiveness matrix's units) or a vehicle given, and reports the difference per motor.

Needs the optional ``pyulog`` package (``pip install pyulog``).  Multicopters only
(``actuator_motors``); control surfaces (``actuator_servos``) are not compared.
"""

from __future__ import annotations

import contextlib
import io
import sys
import math
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._files import MAX_LOG_BYTES, read_user_file
from ..exceptions import AllocError, OptionError, ProblemError
from ..vehicle_file.fields import WRENCH_COMPONENTS
from ._ulog_scan import ULogScan, scan_ulog

__all__ = ["FlightLog", "Replay", "read_ulog", "replay"]

#: the ULog topics read: the allocator's demands and its motor commands
TOPICS = ("vehicle_torque_setpoint", "vehicle_thrust_setpoint", "actuator_motors")


@dataclass(frozen=True)
class FlightLog:
    """Paired samples of a PX4 log: time (s from the log's start), demands (N x 6: roll, pitch,
    yaw torque, then x, y, z thrust, PX4's normalised units), PX4's motor commands (N x motors)."""

    t: np.ndarray
    demand: np.ndarray
    motors: np.ndarray
    params: dict[str, Any]
    software: str = ""


@dataclass(frozen=True)
class Replay:
    """A log replayed with one method: our commands ``u`` beside PX4's, their difference, statuses."""

    method: str
    t: np.ndarray
    v: np.ndarray
    u: np.ndarray
    px4: np.ndarray
    status: tuple[str, ...]
    effector_names: tuple[str, ...]
    axes: tuple[str, ...]

    @property
    def difference(self) -> np.ndarray:
        """``u - px4`` per sample and motor."""
        return self.u - self.px4

    def summary(self) -> dict[str, Any]:
        """Per motor: RMS and largest |difference|; the share of samples each status took."""
        d = self.difference
        statuses = {s: self.status.count(s) / len(self.status) for s in sorted(set(self.status))}
        return {"method": self.method, "samples": int(self.t.size), "effectors": list(self.effector_names),
                "rms_difference": np.sqrt(np.mean(d ** 2, axis=0)).tolist(),
                "max_abs_difference": np.max(np.abs(d), axis=0).tolist(), "status": statuses}

    def rows(self) -> list[dict[str, Any]]:
        """One row per sample: t, the demand by axis, our command, PX4's, the status (CSV)."""
        out = []
        for i in range(self.t.size):
            row: dict[str, Any] = {"t": float(self.t[i])}
            row |= {f"v_{a}": float(self.v[i, j]) for j, a in enumerate(self.axes)}
            row |= {f"u_{n}": float(self.u[i, j]) for j, n in enumerate(self.effector_names)}
            row |= {f"px4_{n}": float(self.px4[i, j]) for j, n in enumerate(self.effector_names)}
            row["status"] = self.status[i]
            out.append(row)
        return out


def read_ulog(path: str | Path) -> FlightLog:
    """The paired demands and motor commands of the ULog at ``path``.

    Bounded before pyulog parses: a regular file of at most :data:`~alloc._files.MAX_LOG_BYTES`
    (:func:`~alloc._files.read_user_file`), whose message structure :func:`._ulog_scan.scan_ulog`
    checked so that pyulog reads each message once (its own recovery can loop forever on one
    flipped byte); pyulog's work is then linear in the messages, at most
    :data:`._ulog_scan.MAX_LOG_MESSAGES`.  Every refusal is a
    :class:`~alloc.exceptions.ProblemError` naming the field: ``ulog`` for the file and its
    structure, ``<topic>.<field>`` for a missing or unusable field, ``CA_ROTOR_COUNT``.

    Motor samples where PX4 commanded NaN (its value for a stopped motor, before arming) or whose
    sample time no setpoint has are not paired; the paired sample times must increase.
    """
    try:
        from pyulog import ULog
        from pyulog.core import ULogException
    except ImportError as exc:
        raise ImportError("reading a ULog needs pyulog: pip install 'alloc-toolkit[ulog]'") from exc
    raw = read_user_file(path, field="ulog", max_bytes=MAX_LOG_BYTES)
    name = Path(path).name
    scan = scan_ulog(raw, name)
    try:
        log = ULog(io.BytesIO(raw), list(TOPICS))
    except (ULogException, ValueError, IndexError, KeyError, TypeError, OverflowError, struct.error,
            RecursionError) as exc:
        raise ProblemError(f"ulog: cannot read {name} as a ULog ({type(exc).__name__}: {exc})",
                           field="ulog") from None
    torque, thrust, motors = _topic_data(log, scan, name)
    torque_t = _sample_times(torque, "vehicle_torque_setpoint")
    thrust_t = _sample_times(thrust, "vehicle_thrust_setpoint")
    _check_increasing(torque_t, "vehicle_torque_setpoint.timestamp_sample")
    _check_increasing(thrust_t, "vehicle_thrust_setpoint.timestamp_sample")
    # PX4 publishes both with the same sample time; a cut log may end between them
    setpoint_t, in_torque, in_thrust = np.intersect1d(torque_t, thrust_t, assume_unique=True, return_indices=True)
    if not setpoint_t.size:
        raise ProblemError("ulog: torque and thrust setpoints share no sample time", field="ulog")
    params = dict(log.initial_parameters)
    n_motors = _rotor_count(params, motors)
    motor_t = _sample_times(motors, "actuator_motors")
    commands = _columns(motors, "actuator_motors", "control", n_motors)
    at = np.searchsorted(setpoint_t, motor_t)
    paired = (at < setpoint_t.size) & (setpoint_t[np.minimum(at, setpoint_t.size - 1)] == motor_t)
    paired &= np.all(np.isfinite(commands), axis=1)
    if not paired.any():
        raise ProblemError("ulog: no motor sample with finite commands has the sample time of a setpoint",
                           field="ulog")
    at = at[paired]
    demand = np.column_stack([_columns(torque, "vehicle_torque_setpoint", "xyz", 3)[in_torque[at]],
                              _columns(thrust, "vehicle_thrust_setpoint", "xyz", 3)[in_thrust[at]]])
    bad = np.argwhere(~np.isfinite(demand))
    if bad.size:
        i, j = bad[0]
        topic = "vehicle_torque_setpoint" if j < 3 else "vehicle_thrust_setpoint"
        raise ProblemError(f"{topic}.xyz[{j % 3}]: not finite at paired sample {i} ({demand[i, j]})",
                           field=f"{topic}.xyz")
    _check_increasing(motor_t[paired], "actuator_motors.timestamp_sample")
    t = _seconds_since(motor_t[paired], log.start_timestamp)
    _check_increasing(t, "actuator_motors.timestamp_sample")  # float64 rounds times past 2**53 us
    return FlightLog(t=t, demand=demand, motors=commands[paired], params=params,
                     software=str(log.msg_info_dict.get("ver_sw", "")))


def _topic_data(log: Any, scan: ULogScan, name: str) -> list[dict[str, np.ndarray]]:
    """The fields of each of :data:`TOPICS` (instance 0) pyulog read, all of the data messages
    the scan counted (a ``struct.error`` silently ends pyulog's read)."""
    if log.file_corruption:
        raise ProblemError(f"ulog: {name} has messages pyulog cannot parse (a damaged log)", field="ulog")
    topics: dict[str, dict[str, np.ndarray]] = {}
    for topic in TOPICS:
        held = [d.data for d in log.data_list if d.name == topic and d.multi_id == 0]
        counted = scan.samples(topic)
        if len(counted) > 1:
            raise ProblemError(f"ulog: {name} subscribes {topic} instance 0 under {len(counted)} message ids",
                               field="ulog")
        if held:
            read = len(next(iter(held[0].values())))
            if read != sum(counted):
                raise ProblemError(f"ulog: {name}: pyulog read {read} of the {sum(counted)} {topic} messages "
                                   "(a damaged log)", field="ulog")
            topics[topic] = held[0]
    missing = [t for t in TOPICS if t not in topics]
    if missing:
        raise ProblemError(f"ulog: {name} has no {', '.join(missing)} (PX4 control_allocator topics, "
                           "v1.13 and later; a multicopter log)", field="ulog")
    return [topics[t] for t in TOPICS]


def _field(data: dict[str, np.ndarray], topic: str, name: str) -> np.ndarray:
    if name not in data:
        raise ProblemError(f"{topic}.{name}: missing", field=f"{topic}.{name.split('[')[0]}")
    return np.asarray(data[name])


def _columns(data: dict[str, np.ndarray], topic: str, name: str, n: int) -> np.ndarray:
    return np.column_stack([_field(data, topic, f"{name}[{i}]").astype(float) for i in range(n)])


def _sample_times(data: dict[str, np.ndarray], topic: str) -> np.ndarray:
    """The topic's ``timestamp_sample``: integer microseconds (PX4's uint64)."""
    t = _field(data, topic, "timestamp_sample")
    if t.dtype.kind not in "iu":
        raise ProblemError(f"{topic}.timestamp_sample: expected integer microseconds, got {t.dtype}",
                           field=f"{topic}.timestamp_sample")
    return t


def _check_increasing(t: np.ndarray, field: str) -> None:
    if t.size > 1:
        bad = np.flatnonzero(~(t[1:] > t[:-1]))
        if bad.size:
            i = int(bad[0]) + 1
            raise ProblemError(f"{field}: does not increase at sample {i} ({t[i - 1]} then {t[i]})", field=field)


def _seconds_since(t: np.ndarray, start: int) -> np.ndarray:
    """``t - start`` in seconds, for increasing integer ``t``: differences taken in integers
    (a uint64 difference wraps, float64 rounds large times)."""
    relative = (t - t[0]).astype(np.uint64)  # exact for increasing int64 or uint64 times
    return relative.astype(float) / 1e6 + (int(t[0]) - int(start)) / 1e6


def _rotor_count(params: dict[str, Any], motors: dict[str, np.ndarray]) -> int:
    """``CA_ROTOR_COUNT``: an integer from 1 to the number of ``actuator_motors.control`` fields."""
    held = 0
    while f"control[{held}]" in motors:
        held += 1
    if not held:
        raise ProblemError("actuator_motors.control[0]: missing", field="actuator_motors.control")
    value = params.get("CA_ROTOR_COUNT")
    if value is None:
        raise ProblemError("CA_ROTOR_COUNT: missing from the log's parameters", field="CA_ROTOR_COUNT")
    whole = isinstance(value, int) and not isinstance(value, bool) or \
        isinstance(value, float) and math.isfinite(value) and value.is_integer()
    if not whole or not 1 <= value <= held:
        raise ProblemError(f"CA_ROTOR_COUNT: expected an integer 1..{held} (the actuator_motors.control fields "
                           f"of the log), got {value!r}" + (f" (actuator_motors.control[{held}]: missing)"
                                                             if isinstance(value, int) and value > held else ""),
                           field="CA_ROTOR_COUNT")
    return int(value)


def replay(log: FlightLog, method: str = "pinv", *, vehicle: Any = None,
           options: dict[str, Any] | None = None) -> Replay:
    """Allocate every demand of ``log`` with ``method`` and set our commands beside PX4's.

    ``vehicle``: a vehicle (name, file, :class:`~alloc.vehicle_file.Vehicle`) whose axes name
    wrench components (``roll`` ... ``fz``) in PX4's normalised units and whose effectors are
    the log's motors in order; default: the log's parameters through
    :func:`~alloc.importers.px4.vehicle_from_params` (``normalize="px4"``).  The demand of an
    axis is the log's setpoint of its component.  Every call gets ``u_prev``, our previous
    command (the first: PX4's), and the time step, so slew limits apply.
    """
    import alloc
    from alloc import vehicles

    from .px4 import vehicle_from_params

    fv = vehicle_from_params(log.params, name="ulog", normalize="px4") if vehicle is None else \
        vehicles.get_vehicle(vehicle)
    if fv.m != log.motors.shape[1]:
        raise ProblemError(f"vehicle: {fv.m} effectors, but the log commands {log.motors.shape[1]} motors",
                           field="vehicle")
    rows = []
    for i, a in enumerate(fv.axes):
        if a.component is None:
            raise ProblemError(f"axes[{i}].wrench: the replay needs each axis's wrench component "
                               f"({', '.join(WRENCH_COMPONENTS)})", field=f"axes[{i}].wrench")
        rows.append(WRENCH_COMPONENTS.index(a.component))
    V = log.demand[:, rows]
    allocate = alloc.make_allocator(fv.problem(), method, **vehicles.method_options(fv, method, options))
    U = np.empty((V.shape[0], fv.m))
    status = []
    u_prev = log.motors[0]
    for i in range(V.shape[0]):
        dt = float(log.t[i] - log.t[i - 1]) if i else math.nan
        res = allocate(V[i], u_prev=u_prev, dt=dt) if i and dt > 0 else allocate(V[i])
        U[i] = res.u
        status.append(str(res.status.value if hasattr(res.status, "value") else res.status))
        u_prev = U[i]
    return Replay(method=method, t=log.t, v=V, u=U, px4=log.motors, status=tuple(status),
                  effector_names=fv.effector_names, axes=fv.axis_names)


# --------------------------------------------------------------------------- command line
def replay_command() -> Any:
    """The typer command ``alloc replay --ulog LOG.ulg [--vehicle NAME|FILE] --method M [--csv F] [--json F]``."""
    import json

    import typer

    from ..cli import VEHICLE_HELP, load_vehicle_option, output_file, parse_options

    def command(
        ulog: Path = typer.Option(..., "--ulog", help="a PX4 ULog (.ulg) with control_allocator topics"),
        vehicle: str | None = typer.Option(None, "--vehicle", metavar="NAME|FILE",
                                              help=f"{VEHICLE_HELP}; default: the log's own parameters (PX4 "
                                              "normalisation)"),
        method: str = typer.Option("pinv", "--method", help="allocation method (see `alloc methods`)"),
        option: list[str] = typer.Option([], "--option", help="method option key=value; repeatable"),
        csv_path: Path | None = typer.Option(None, "--csv", help="write every sample to this new file"),
        json_path: Path | None = typer.Option(None, "--json", help="write the summary to this new file"),
        force: bool = typer.Option(False, "--force", help="overwrite output files that exist"),
    ) -> None:
        """Replay a PX4 log's demands through an allocator; print how our commands differ from PX4's (JSON)."""
        taken: dict[Path, str] = {}
        for path, hint in ((csv_path, "--csv"), (json_path, "--json")):
            output_file(path, force, hint, taken=taken)
        chosen = None if vehicle is None else load_vehicle_option(vehicle)
        options = parse_options(option)
        try:  # the log and, without --vehicle, the vehicle of its parameters
            # pyulog prints its warnings to stdout, where this command writes its JSON; the swap
            # of sys.stdout is the command's (one thread), never the library's
            with contextlib.redirect_stdout(sys.stderr):
                flight = read_ulog(ulog)
            if chosen is None:
                from .px4 import vehicle_from_params

                chosen = vehicle_from_params(flight.params, name="ulog", normalize="px4")
        except AllocError as exc:
            raise typer.BadParameter(str(exc), param_hint="--ulog") from None
        except ImportError as exc:  # the optional extra is absent: one line, exit 2, like every input error
            raise typer.BadParameter(str(exc), param_hint="--ulog") from None
        try:
            result = replay(flight, method, vehicle=chosen, options=options)
        except AllocError as exc:
            field = exc.field or ""
            hint = "--vehicle" if field == "vehicle" or field.startswith("axes") else \
                "--option" if isinstance(exc, OptionError) else "--method"
            raise typer.BadParameter(str(exc), param_hint=hint) from None
        summary = result.summary()
        typer.echo(json.dumps(summary, indent=2))
        if json_path is not None:
            json_path.write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
        if csv_path is not None:
            rows = result.rows()
            lines = [",".join(rows[0])] + [",".join(str(r[k]) for k in rows[0]) for r in rows]
            csv_path.write_text("\n".join(lines) + "\n", encoding="utf-8")

    return command


if __name__ == "__main__":  # python -m alloc.importers.ulog --ulog LOG.ulg --method qp
    import typer

    typer.run(replay_command())
