"""The seed's printed numbers reproduced by the project's own allocator."""

from __future__ import annotations

import numpy as np
import pytest

import alloc
from alloc.methods.pseudo_inverse import distribution_matrix
from alloc.vehicles import bundled, harv_latdir, ice, ice_mid

# seed Eq 4.24 and Eq 4.19 as the files carry them ([simulation.allocation] static)
ICE_BK_SEED = np.array(bundled("ice").simulation.allocation.static)
HARV_LATDIR_BK_SEED = np.array(bundled("harv").simulation.allocation.static)

# seed Eq 4.24 as printed, kept as text to know each entry's printed precision
EQ_4_24 = """-0.773 0.107 -0.097
-0.773 -0.107 0.097
-1.33 0 0
-0.485 0.048 0.055
-0.485 -0.048 -0.055
0 -0.104 1.06
0 0.104 -1.06
0.560 -0.0920 -1.73
0.560 0.0920 1.73
-0.715 0 0
0 0.01 6.87"""


def last_digit(s: str) -> float:
    decimals = len(s.split(".")[1]) if "." in s else 0
    return 10.0**-decimals


def test_pinv_reproduces_eq_4_24():
    """seed Eq 4.23/4.24: W_u = diag[2,2,1,...], spoilers removed from the pitch channel,
    rows (w-dot, p-dot, v-dot) of the ICE B.  Every entry within one unit of the printed
    last digit: the seed's printing mixes rounding and truncation (-0.4849 is printed
    -0.485, but 0.0555 is printed 0.055 and -0.0975 is printed -0.097)."""
    P = alloc.make_allocator(ice(design=True), "pinv").impl.P
    printed = [line.split() for line in EQ_4_24.splitlines()]
    for i, row in enumerate(printed):
        for j, s in enumerate(row):
            assert abs(P[i, j] - float(s)) <= last_digit(s) + 1e-12, (i, j, P[i, j], s)
    np.testing.assert_array_equal(np.array(printed, dtype=float), ICE_BK_SEED)


def test_eq_4_24_needs_the_seed_choices():
    """Without the spoiler removal or the elevon weights the printed matrix is not reproduced."""
    P_true_B = distribution_matrix(ice())
    assert np.abs(P_true_B - ICE_BK_SEED).max() > 0.1
    P_no_w = distribution_matrix(ice(design=True).replace(Wu=np.ones(11)))
    assert np.abs(P_no_w - ICE_BK_SEED).max() > 0.05


def test_harv_ganging_is_eq_4_19():
    p = harv_latdir()
    # Eq 4.19 maps the (beta, p) pseudo-commands; as a 3-axis gang it acts on (beta-dot, p-dot, r-dot)
    G = np.zeros((5, 3))
    G[:, 0], G[:, 1] = HARV_LATDIR_BK_SEED[:, 0], HARV_LATDIR_BK_SEED[:, 1]
    r = alloc.allocate(p, [1.0, 2.0, 0.0], "ganging", G=G)
    np.testing.assert_allclose(r.u, [1.2, 2.0, 1.0, 1.2, 0.6])


# ------------------------------------------------------------------ the catalogue
SEED_NAMES = ["ice", "ice-design", "ice-mid", "harv"]
EXAMPLES = ["hexa-x", "tailless", "x57-dep"]


def test_every_command_names_the_same_problems_the_same_way():
    """alloc allocate --vehicle, alloc ams --vehicle and the sweep use one catalogue."""
    import json

    from typer.testing import CliRunner

    from alloc import vehicles
    from alloc.ams.cli import app as ams_app
    from alloc.cli import app

    runner = CliRunner()
    listed = json.loads(runner.invoke(app, ["vehicles", "--json"]).output)
    assert [row["name"] for row in listed] == vehicles.names() == SEED_NAMES + EXAMPLES
    for name in vehicles.names() + ["harv_latdir"]:
        p = vehicles.problem(name)
        out = runner.invoke(app, ["allocate", "--vehicle", name, "--v", ",".join(["0.1"] * p.k), "--json"])
        assert out.exit_code == 0, out.output
        assert json.loads(out.output)["names"] == list(p.names)
        out = runner.invoke(ams_app, ["summary", "--vehicle", name, "--json"])
        assert out.exit_code == 0, out.output
    bad = runner.invoke(app, ["allocate", "--vehicle", "f22", "--v", "0"], env={"COLUMNS": "200"})
    assert bad.exit_code == 2
    assert "unknown 'f22'; known: ice, ice-design, ice-mid, harv, hexa-x, tailless" in bad.output


@pytest.mark.parametrize("name", SEED_NAMES)
def test_seed_functions_read_the_bundled_files(name):
    """ice(), ice_mid(), harv_latdir() are the catalogue's problems: one definition, the file."""
    from alloc import vehicles

    make = {"ice": ice, "ice-design": lambda: ice(design=True), "ice-mid": ice_mid, "harv": harv_latdir}[name]
    p, q = vehicles.problem(name), make()
    for f in ("B", "umin", "umax", "up", "Wu", "Wv", "rate_min", "rate_max"):
        a, b = getattr(p, f), getattr(q, f)
        assert a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes(), f
    assert p.names == q.names and p.axes == q.axes


def test_ice_files_agree_with_each_other_and_the_model():
    """seed section 4.7: the allocation rows are (w-dot, pb-dot, v-dot) of the model's B; the design
    problem of Eq 4.24 zeroes the SSD pitch entries and weights the elevons 2 (Eq 4.23); ice-mid
    prefers mid-range on the one-sided AMT/SSD; the loop allocates with the design problem."""
    v = bundled("ice")
    B = v.model.arrays()[1]
    states = list(v.model.states)
    p = ice()
    np.testing.assert_array_equal(p.B, B[[states.index("w"), states.index("pb"), states.index("v")]])
    design = ice(design=True)
    expected = p.B.copy()
    expected[0, [p.names.index("ssd_l"), p.names.index("ssd_r")]] = 0.0
    np.testing.assert_array_equal(design.B, expected)
    np.testing.assert_array_equal(np.diag(design.Wu), [2, 2, 1, 1, 1, 1, 1, 1, 1, 1, 1])
    np.testing.assert_array_equal(v.simulation.allocation.B, design.B)
    np.testing.assert_array_equal(v.simulation.allocation.weights, np.diag(design.Wu))
    mid = ice_mid()
    one_sided = p.umin >= 0
    np.testing.assert_array_equal(mid.up[one_sided], 30.0)
    np.testing.assert_array_equal(mid.up[~one_sided], p.up[~one_sided])
    # seed Table 4-5: limits (deg) and rates (deg/s)
    np.testing.assert_array_equal(p.umax, [30, 30, 30, 60, 60, 60, 60, 40, 40, 15, 15])
    np.testing.assert_array_equal(p.rate_max, [150, 150, 50, 150, 150, 150, 150, 40, 40, 60, 60])


def test_harv_file_agrees_with_its_model():
    """seed Eq 4.16: the allocation problem is the model's B (states beta, p, r); Table 4-3 limits."""
    v = bundled("harv")
    _, B, C, _ = v.model.arrays()
    p = harv_latdir()
    np.testing.assert_array_equal(p.B, B)
    np.testing.assert_array_equal(p.umax, [17.5, 27.5, 30, 30, 30])
    np.testing.assert_array_equal(p.rate_max, [60, 100, 100, 60, 60])
    np.testing.assert_array_equal(v.simulation.allocation.B, C[[0, 3]] @ B)  # beta-dot and ps-dot rows


def test_catalogue_entries_and_aliases():
    from alloc import vehicles

    np.testing.assert_array_equal(vehicles.problem("harv_latdir").B, vehicles.harv_latdir().B)
    np.testing.assert_array_equal(vehicles.problem("ice-design").B, vehicles.ice(design=True).B)
    mid = vehicles.problem("ice-mid")
    np.testing.assert_array_equal(mid.up[mid.umin >= 0], 30.0)  # AMT/SSD 0..60 deg prefer mid-range
    for name in SEED_NAMES + ["tailless"]:
        p = vehicles.problem(name)
        groups = vehicles.daisy_groups(name)
        assert sorted(e for g in groups for e in g) == sorted(p.names)  # each effector in one group
        assert alloc.allocate(p, p.B @ p.up, "daisy", groups=groups).status.value == "exact"
    with pytest.raises(alloc.OptionError, match="groups: vehicle 'hexa-x' declares no daisy groups") as info:
        vehicles.daisy_groups("hexa-x")
    assert info.value.field == "groups"
    with pytest.raises(alloc.ProblemError, match="vehicle: unknown 'x'") as info:
        vehicles.problem("x")
    assert info.value.field == "vehicle"
    assert vehicles.CATALOGUE["harv"].aliases == ("harv_latdir", "harv-latdir")
    assert vehicles.lookup("harv_latdir").title == "F-18/HARV lat-dir"


def test_seed_numbers_live_only_in_the_files():
    """One definition: no Python module under alloc/ or sim/ repeats a distinctive number of the
    seed's files (their B, model and failure matrices with 7 or more significant digits: ICE's
    and the failed plants'; the HARV's printed 4-digit entries are too short to search for, and
    round numbers such as limits are shared by chance).  Before the files became the source,
    alloc/vehicles.py held 34 of these numbers and sim/scenarios/ice.py 56."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    numbers: set[str] = set()
    for name in ("ice", "harv"):
        v = bundled(name)
        arrays = [np.asarray(a, dtype=float) for a in v.model.arrays()] + [np.asarray(v.problem().B)]
        for spec in v.simulation.failures.values():
            arrays += [np.asarray(a, dtype=float) for a in (spec.A, spec.B, spec.D) if a is not None]
        for a in arrays:
            numbers |= {repr(abs(float(x))) for x in a.ravel() if len(re.sub(r"[^0-9]", "", repr(abs(float(x)))).strip("0")) >= 7}
    assert len(numbers) > 100
    found = {}
    for path in [*(root / "alloc").rglob("*.py"), *(root / "sim").rglob("*.py")]:
        text = path.read_text()
        hits = [n for n in numbers if re.search(rf"(?<![0-9.]){re.escape(n)}(?![0-9])", text)]
        if hits:
            found[str(path.relative_to(root))] = hits[:3]
    assert found == {}
