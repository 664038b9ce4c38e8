"""The allocation contract checked on one hostile case (:mod:`hostile`).

``check(case)`` builds and calls it and returns the contract violations (empty when it
holds): only ``AllocError``/``TypeError`` may escape, with the field named; every ``u``
finite and within the call's bounds; ``v_achieved = B u`` finite; status ``exact`` iff
``B u = v`` within tolerance; the result owns read-only arrays; ``allocate_batch`` equals
the single calls; no call costs more than ``CALL_LIMIT`` CPU seconds (or its method's
declared call cost, if larger) and no build more than ``BUILD_LIMIT`` (CPU seconds of the
calling thread, the registry's unit; wall-clock limits, ``CALL_WALL_LIMIT`` and
``BUILD_WALL_LIMIT``, are only a backstop against waiting and hangs).  With issue 22's
classes: a non-real value is never accepted; the health API raises only ``AllocError``
naming a health field, a failed problem never leaves the nominal limits, rate limits or
effectiveness, and health round-trips through JSON; a round-tripped allocator answers every
call and the batch bit for bit as the original, and round-tripped results are read-only.
"""

from __future__ import annotations

import re
import time
import traceback
from collections import Counter
from typing import Any

import numpy as np

from hostile_cases import decode

# Time is checked as the registry promises it: CPU seconds of the calling thread
# (``time.thread_time``: the case's own work, whatever else the machine runs; a single call
# and a build run on the caller's thread, and at these sizes BLAS does not start threads of
# its own; ``process_time`` would also count the solver libraries' idle pools and costs
# milliseconds a read in a process with many threads), with wall-clock limits only as a
# backstop for calls that wait instead of compute (a lock never released, a hang).
#: CPU seconds: a call costing more than this, or more than its method's declared
#: ``Method.call_cost`` where that is larger, is a failure (a case is at most 6 x 12, where
#: the declared costs are milliseconds; :data:`alloc.registry.CALL_LIMIT_SECONDS` bounds them
#: at the size caps)
CALL_LIMIT = 1.0
#: CPU seconds: a build costing more than this is a failure (the registry refuses or
#: redirects builds declared beyond :data:`alloc.registry.BUILD_LIMIT_SECONDS`, 20 s)
BUILD_LIMIT = 30.0
#: wall seconds: the backstops (a case's watchdog budget is built from them)
CALL_WALL_LIMIT, BUILD_WALL_LIMIT = 20.0, 120.0
PROBLEM_FIELDS = ("B", "umin", "umax", "up", "Wu", "Wv", "rate_min", "rate_max", "names", "axes")
DEMAND_FIELDS = ("v", "u_prev", "dt", "V")
#: batch row vs single call, relative to the moments' scale: vectorised arithmetic differs
#: from the compiled single call only in rounding order
BATCH_RTOL = 1e-9
#: the fields a health-API refusal may name
HEALTH_FIELDS = ("effector", "kind", "position", "fraction", "lo", "hi", "rate_min", "rate_max", "limits",
                 "rate_limits", "jam_position", "floating", "effectiveness", "health", "event")


# ----------------------------------------------------------------------------- contract
def _names_field(exc: BaseException, fields: tuple[str, ...]) -> bool:
    msg = str(exc)
    return any(re.search(rf"(^|[\s:(\[]){re.escape(f)}([\s:\[\]/=(]|$)", msg) for f in fields)


def _honest(B: np.ndarray, r: Any, v: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> list[str]:
    """Violations of the result contract for one call (empty when it holds)."""
    from alloc.result import EXACT_RTOL

    bad = []
    u, va = r.u, r.v_achieved
    if u.shape != lo.shape or not np.isfinite(u).all():
        return [f"non-finite or misshapen u {u!r}"]
    if (u < lo).any() or (u > hi).any():
        return [f"inadmissible u: violation {max((lo - u).max(), (u - hi).max()):g}"]
    if not (np.isfinite(va).all() and np.isfinite(r.unallocated).all()):
        return ["non-finite v_achieved or unallocated"]
    Bu = B @ u
    scale = np.abs(B) @ np.abs(u) + 1e-300
    if (np.abs(Bu - va) > 1e-9 * scale + 1e-300).any():
        bad.append("v_achieved != B u")
    if not np.array_equal(r.v, v):
        bad.append("result's v is not the demand")
    for a in (r.u, r.v, r.v_achieved):
        if a.flags.writeable:
            bad.append("result array is writeable")
            break
    err = float(np.abs(Bu - v).max())
    tol = EXACT_RTOL * max(1.0, float(np.abs(v).max()))
    # round-off margin: B u evaluated by BLAS here and by the compiled kernel there
    margin = 1e-9 * float(scale.max()) + 1e-12 * tol
    if r.status.value == "exact" and not err <= tol + margin:
        bad.append(f"dishonest exact: |Bu - v| = {err:g} > {tol:g}")
    if r.status.value == "unattainable" and not err > tol - margin:
        bad.append(f"dishonest unattainable: |Bu - v| = {err:g} <= {tol:g}")
    return bad


def check(c: dict[str, Any]) -> dict[str, Any]:
    """Run case ``c``; ``{"fail": [...], "status": {...}, "refused": str}``."""
    import alloc
    from alloc.exceptions import AllocError

    out: dict[str, Any] = {"fail": [], "status": Counter(), "refused": ""}
    fail = out["fail"]
    hostile = c.get("hostile")

    def refused_right(stage: str, exc: BaseException, fields: tuple[str, ...]) -> None:
        """A refusal at ``stage``: it must name the case's non-real field when it has one there."""
        if hostile is not None and hostile["where"] == stage:
            fields = (hostile["field"],)
        if not _names_field(exc, fields):
            fail.append(f"{stage} error names no field: {type(exc).__name__}: {exc}")

    try:
        p = alloc.Problem(**decode(c["fields"]))
    except (AllocError, TypeError) as exc:
        refused_right("problem", exc, PROBLEM_FIELDS + ("umin/umax",))
        out["refused"] = "problem"
        return out
    except Exception as exc:  # noqa: BLE001 - the contract under test
        fail.append(f"escaped at Problem: {type(exc).__name__}: {exc}")
        return out
    if hostile is not None and hostile["where"] == "problem":
        fail.append(f"accepted a {hostile['kind']} value in {hostile['field']}")
        return out
    d = p.to_dict()
    if alloc.Problem(**d).to_dict() != d:
        fail.append("to_dict -> Problem(**d) does not round-trip")
    if "round_trip" in c:
        fail.extend(_problem_round_trip(p, c["round_trip"]))
    if "health" in c:
        p = _apply_health(p, c["health"], fail)
        if p is None:
            return out
    t0, c0 = time.perf_counter(), time.thread_time()
    try:
        f = alloc.make_allocator(p, c["method"], **decode(c["options"]))
    except (AllocError, TypeError) as exc:
        refused_right("option", exc, tuple(c["options"]) + PROBLEM_FIELDS)
        out["refused"] = "options"
        return out
    except Exception as exc:  # noqa: BLE001
        fail.append(f"escaped at build: {type(exc).__name__}: {exc}\n{traceback.format_exc(limit=-3)}")
        return out
    build_cpu, build_wall = time.thread_time() - c0, time.perf_counter() - t0
    if build_cpu > BUILD_LIMIT or build_wall > BUILD_WALL_LIMIT:
        fail.append(f"slow build: {build_cpu:.2f} CPU s, {build_wall:.2f} s wall")
    if hostile is not None and hostile["where"] == "option":
        fail.append(f"accepted a {hostile['kind']} value in option {hostile['field']}")
        return out
    call_limit = max(CALL_LIMIT, _declared_call_cost(p, c["method"], decode(c["options"])))
    twin = None
    if "round_trip" in c:
        twin = _allocator_round_trip(f, c["round_trip"], fail)
    singles = []
    for call in c["calls"]:
        kw = {x: decode(call[x]) for x in ("u_prev", "dt") if x in call}
        if "hostile" in call:
            v_in = decode(call["v"])
        else:
            v_in = np.array(call["v"], dtype=float) if _plain(call["v"]) else call["v"]
        t0, c0 = time.perf_counter(), time.thread_time()
        try:
            r = f(v_in, **kw)
        except (AllocError, TypeError) as exc:
            fields = (call["hostile"],) if "hostile" in call else DEMAND_FIELDS + ("u_prev/dt",)
            if not _names_field(exc, fields):
                fail.append(f"call error names no field: {type(exc).__name__}: {exc}")
            continue
        except Exception as exc:  # noqa: BLE001
            fail.append(f"escaped at call: {type(exc).__name__}: {exc}\n{traceback.format_exc(limit=-3)}")
            continue
        cpu, wall = time.thread_time() - c0, time.perf_counter() - t0
        if cpu > call_limit or wall > CALL_WALL_LIMIT:
            fail.append(f"slow call: {cpu:.2f} CPU s (limit {call_limit:.2g}), {wall:.2f} s wall")
        if "hostile" in call:
            fail.append(f"accepted a non-real value in {call['hostile']}: {str(call[call['hostile']])[:80]}")
            continue
        if twin is not None:
            fail.extend(_twin_agrees(twin, r, v_in, kw, c["round_trip"]))
        v = np.asarray(r.v)
        lo, hi = p.effective_bounds(kw.get("u_prev"), kw.get("dt")) if kw else (p.umin, p.umax)
        snapshot = (r.u.copy(), r.v.copy())
        if isinstance(v_in, np.ndarray):
            v_in[...] = 99.0  # the caller reuses its array: the result must not change
            if not (np.array_equal(r.u, snapshot[0]) and np.array_equal(r.v, snapshot[1])):
                fail.append("result changed when the caller's demand array changed")
        fail.extend(_honest(p.B, r, v, lo, hi))
        out["status"][r.status.value] += 1
        if r.status.value == "fallback":
            out.setdefault("messages", []).append(r.message[:120])
        if not kw:
            singles.append(r)
    if "batch_V" in c:
        try:
            f.batch(decode(c["batch_V"]))
        except (AllocError, TypeError) as exc:
            if not _names_field(exc, ("V",)):
                fail.append(f"batch error names no field: {type(exc).__name__}: {exc}")
        except Exception as exc:  # noqa: BLE001
            fail.append(f"escaped at batch: {type(exc).__name__}: {exc}")
        else:
            fail.append(f"accepted a non-real value in V: {str(c['batch_V'])[:80]}")
    if singles:
        # Batch equals single, on the same long-lived allocator after its single calls (so
        # this also checks that answers do not depend on call history).
        V = np.array([r.v for r in singles])
        try:
            br = f.batch(V)
        except Exception as exc:  # noqa: BLE001 - valid demands: batch must not raise
            fail.append(f"escaped at batch: {type(exc).__name__}: {exc}")
        else:
            fail.extend(_batch_equals_single(p.B, br, singles))
            if twin is not None:
                tb = twin.batch(V)
                if not (tb.u.tobytes() == br.u.tobytes() and list(tb.status) == list(br.status)):
                    fail.append(f"round trip ({c['round_trip']}): batch differs from the original's")
    return out


def _declared_call_cost(p: Any, method: str, options: dict[str, Any]) -> float:
    """The method's declared worst-case CPU seconds per call (:meth:`alloc.registry.Method.call_cost`)."""
    import alloc.registry

    return float(alloc.registry.get_method(method).call_cost(p, **options))


def _trip(how: str) -> Any:
    import copy
    import pickle

    return {"pickle": lambda x: pickle.loads(pickle.dumps(x)), "copy": copy.copy, "deepcopy": copy.deepcopy}[how]


def _problem_round_trip(p: Any, how: str) -> list[str]:
    q = _trip(how)(p)
    arrays = ("B", "umin", "umax", "up", "Wu", "Wv", "rate_min", "rate_max")
    bad = [f"round trip ({how}): Problem.{a} differs" for a in arrays
           if getattr(p, a).tobytes() != getattr(q, a).tobytes()]
    bad += [f"round trip ({how}): Problem.{a} writeable" for a in arrays if getattr(q, a).flags.writeable]
    if (q.names, q.axes) != (p.names, p.axes):
        bad.append(f"round trip ({how}): Problem names differ")
    return bad


def _allocator_round_trip(f: Any, how: str, fail: list[str]) -> Any:
    """``f`` after ``how`` (``None`` when that fails: a failure of the case)."""
    try:
        return _trip(how)(f)
    except Exception as exc:  # noqa: BLE001 - every allocator pickles (protocol >= 2)
        fail.append(f"round trip ({how}) of the allocator failed: {type(exc).__name__}: {exc}\n"
                    f"{traceback.format_exc(limit=-3)}")
        return None


def _twin_agrees(twin: Any, r: Any, v_in: Any, kw: dict[str, Any], how: str) -> list[str]:
    """The round-tripped allocator answers ``v_in`` bit for bit as the original did; the
    result itself round-trips with read-only arrays."""
    try:
        t = twin(v_in, **kw)
    except Exception as exc:  # noqa: BLE001
        return [f"round trip ({how}): the copy raised {type(exc).__name__}: {exc}"]
    bad = []
    if not (t.u.tobytes() == r.u.tobytes() and t.v_achieved.tobytes() == r.v_achieved.tobytes()
            and t.status is r.status):
        bad.append(f"round trip ({how}): answer differs from the original's ({r.status.value} -> {t.status.value})")
    rr = _trip(how)(r)
    if any(a.flags.writeable for a in (rr.u, rr.v, rr.v_achieved, rr.unallocated)):
        bad.append(f"round trip ({how}): result array writeable")
    if rr.u.tobytes() != r.u.tobytes() or rr.status is not r.status:
        bad.append(f"round trip ({how}): result differs")
    return bad


def _apply_health(p: Any, h: dict[str, Any], fail: list[str]) -> Any:
    """Apply case ``h``'s events and records to ``p``; the failed problem, or ``None``.

    Every refusal is a ProblemError naming a health field; the failed problem keeps within
    the nominal one (limits, rate limits, effectiveness <= 1) and its health round-trips
    through JSON."""
    from alloc.exceptions import AllocError
    from alloc.health import EffectorHealth, FailureEvent, apply_event, health_from_dict, health_to_dict

    def refused(stage: str, exc: BaseException) -> None:
        if stage == "record" and type(exc) is TypeError and "unexpected keyword argument" in str(exc):
            return  # a constructor given an unknown field: Python's own TypeError names it
        if not isinstance(exc, AllocError):
            fail.append(f"health {stage} escaped: {type(exc).__name__}: {exc}")
        elif not _names_field(exc, HEALTH_FIELDS):
            fail.append(f"health {stage} error names no field: {exc}")

    health: dict[str, Any] = {}
    for ev in h["events"]:
        try:
            _, health = apply_event(p, health, FailureEvent(**ev))
        except Exception as exc:  # noqa: BLE001 - the contract under test
            refused("event", exc)
    name = p.names[h["record_effector"]]
    for stage, make in (("record", lambda: EffectorHealth(**h["record"])),
                        ("from_dict", lambda: health_from_dict({name: h["record"]})[name])):
        try:
            rec = make()
        except Exception as exc:  # noqa: BLE001
            refused(stage, exc)
            continue
        if not isinstance(h["record"].get("floating", False), bool):
            fail.append(f"health {stage} accepted floating = {h['record'].get('floating')!r}")
        health = {**health, name: rec}
    try:
        if health_from_dict(health_to_dict(health)) != health:
            fail.append("health does not round-trip through health_to_dict/health_from_dict")
        q = p.with_health(health)
    except Exception as exc:  # noqa: BLE001
        refused("with_health", exc)
        return None
    tol = 0.0
    if ((q.umin < p.umin - tol).any() or (q.umax > p.umax + tol).any() or (q.rate_min < p.rate_min).any()
            or (q.rate_max > p.rate_max).any() or (np.abs(q.B) > np.abs(p.B)).any()):
        fail.append("with_health widened a limit or raised an effectiveness")
    if (q.up < q.umin).any() or (q.up > q.umax).any():
        fail.append("with_health left up outside the limits")
    return q


def _plain(v: Any) -> bool:
    try:
        a = np.array(v, dtype=float)
    except (TypeError, ValueError, OverflowError):
        return False
    return a.ndim == 1


def _batch_equals_single(B: np.ndarray, br: Any, singles: list[Any]) -> list[str]:
    from alloc.result import EXACT_RTOL

    bad = []
    for i, r in enumerate(singles):
        scale = max(1.0, float(np.abs(r.v).max()), float((np.abs(B) @ np.abs(r.u)).max()))
        if np.abs(br.v_achieved[i] - r.v_achieved).max() > BATCH_RTOL * scale:
            bad.append(f"batch row {i}: B u {br.v_achieved[i]} != single {r.v_achieved} ({r.status.value})")
            continue
        if br.status[i] != r.status.value:
            err = float(np.abs(B @ r.u - r.v).max())
            tol = EXACT_RTOL * max(1.0, float(np.abs(r.v).max()))
            if abs(err - tol) > 1e-3 * tol and "fallback" not in (br.status[i], r.status.value):
                bad.append(f"batch row {i}: status {br.status[i]} != single {r.status.value}")
    return bad
