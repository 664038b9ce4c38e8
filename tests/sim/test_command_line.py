"""``alloc sim``: flags, exports, exit code on divergence, reproducible command lines."""

from __future__ import annotations

import json

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from sim.cli import EXIT_DIVERGED, command_line, sim_command

app = typer.Typer()
app.command()(sim_command)
runner = CliRunner()


def test_flags_reach_the_run_and_exports_are_written(tmp_path):
    csv, js, png = tmp_path / "r.csv", tmp_path / "r.json", tmp_path / "r.png"
    res = runner.invoke(app, [
        "harv_lon", "--method", "pinv", "--failure", "failure2", "--failure-time", "0.5", "--duration", "1",
        "--no-noise", "--pilot", "crossover", "--pilot-gain", "1.5", "--frame-rate", "400", "--rate-blind",
        "--told", "--csv", str(csv), "--json", str(js), "--plot", str(png),
    ])
    assert res.exit_code == 0, res.output
    summary = json.loads(js.read_text())
    s = summary["settings"]
    assert s["frame_period"] == 0.0025 and s["rate_aware"] is False and s["allocator_knows_failure"] is True
    assert s["noise"] is False and s["pilots"][0]["model"] == "crossover" and s["pilots"][0]["gain"] == 1.5
    assert summary["failure_time"] == 0.5 and summary["allocator_calls"] == 401
    header = csv.read_text().splitlines()[0].split(",")
    assert header[:3] == ["t", "ref_q", "out_q"] and "pos_ptv" in header and header[-1] == "alloc_status"
    assert png.stat().st_size > 10_000


def test_parquet_round_trips_against_the_csv(tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    csv, parquet = tmp_path / "r.csv", tmp_path / "r.parquet"
    res = runner.invoke(app, ["ice", "--method", "qp", "--failure", "seed", "--failure-time", "0.3", "--duration", "0.6",
                              "--no-noise", "--frame-rate", "400", "--csv", str(csv), "--parquet", str(parquet)])
    assert res.exit_code == 0, res.output
    table = pq.read_table(parquet)
    lines = csv.read_text().splitlines()
    header = lines[0].split(",")
    assert table.column_names == header and table.num_rows == len(lines) - 1 == 121
    rows = [line.split(",") for line in lines[1:]]
    for j, name in enumerate(header):
        col = table.column(name).to_pylist()
        if name == "alloc_status":
            assert col == [r[j] for r in rows] and set(col) <= {"exact", "unattainable", "fallback"}
        else:  # the CSV keeps 9 significant digits, Parquet the float64 itself
            np.testing.assert_allclose(col, [float(r[j]) for r in rows], rtol=1e-8, atol=1e-300)
    meta = json.loads(table.schema.metadata[b"alloc.sim"])
    assert meta["scenario"] == "ice" and meta["failure_time"] == 0.3 and meta["settings"]["frame_period"] == 0.0025


def test_diverged_run_exits_non_zero():
    # The seed's ICE SMC law (--boundary-layer fixed --anti-windup off) sampled at 100 Hz diverges
    # before 5 s (measured 4.05 s): see README, Frame rate.
    res = runner.invoke(app, ["ice", "--method", "pinv", "--duration", "5", "--no-noise", "--pilot-gain", "1",
                              "--frame-rate", "100", "--rate-blind", "--boundary-layer", "fixed",
                              "--anti-windup", "off"])
    assert res.exit_code == EXIT_DIVERGED
    assert "diverged at t =" in res.output


def test_bad_frame_rate_is_a_usage_error():
    res = runner.invoke(app, ["ice", "--frame-rate", "300", "--duration", "0.1"])
    assert res.exit_code == 2  # 1/300 s is not a multiple of the 0.5 ms step
    assert "frame_period" in res.output


def test_command_line_round_trips_the_options():
    line = command_line("ice", method="qp", failure="seed", allocator_knows_failure=True, frame_period=0.01,
                        rate_aware=True, noise=False, pilot="crossover")
    assert line == ("alloc sim ice --method qp --failure seed --told --frame-rate 100 --rate-aware --no-noise "
                    "--pilot crossover")


def _histories(path) -> dict[str, np.ndarray]:
    lines = path.read_text().splitlines()
    header = lines[0].split(",")[:-1]  # the last column is the allocator status
    table = np.array([[float(x) for x in line.split(",")[:-1]] for line in lines[1:]])
    return {name: table[:, j] for j, name in enumerate(header)}


def test_harv_latdir_failure2_injects_its_failure_by_default(tmp_path):
    # issue 22: `alloc sim harv_latdir_failure2` (the README's Fig 4-81 command) ran nominal, because
    # the command passed failure=None over the scenario's own default
    failed_csv, nominal_csv = tmp_path / "failed.csv", tmp_path / "nominal.csv"
    failed = runner.invoke(app, ["harv_latdir_failure2", "--duration", "6", "--no-noise", "--csv", str(failed_csv)])
    assert failed.exit_code == 0, failed.output
    nominal = runner.invoke(app, ["harv_latdir_failure2", "--duration", "6", "--no-noise", "--failure", "none",
                                  "--csv", str(nominal_csv)])
    assert nominal.exit_code == 0, nominal.output
    assert json.loads(failed.stdout)["failure"] == "failure2" and json.loads(failed.stdout)["failure_time"] == 0.0
    assert json.loads(nominal.stdout)["failure"] is None
    hist, ref = _histories(failed_csv), _histories(nominal_csv)
    # Failure #2 (seed 4.6): yaw thrust vector limited to +-3 deg at 10 % effectiveness; the
    # filtered bank-angle steps drive it to that limit and the rudder (30 deg limit) takes over
    assert np.abs(hist["pos_yaw_tv"]).max() == pytest.approx(3.0, abs=1e-9)
    assert np.abs(hist["pos_rudder"]).max() > 20.0
    assert np.abs(ref["pos_yaw_tv"]).max() < 2.5 and np.abs(ref["pos_rudder"]).max() < 5.0


def test_outputs_never_overwrite_an_existing_file_unless_forced(tmp_path):
    # issue 22: the README's `alloc sim ice ... --json docs/... --plot docs/...` overwrote two tracked files
    js, png = tmp_path / "tracked.json", tmp_path / "tracked.png"
    js.write_text("tracked"), png.write_bytes(b"tracked")
    args = ["ice", "--method", "qp", "--duration", "0.05", "--no-noise", "--json", str(js), "--plot", str(png)]
    refused = runner.invoke(app, args)
    assert refused.exit_code == 2 and "--force" in refused.stderr
    assert js.read_text() == "tracked" and png.read_bytes() == b"tracked"
    forced = runner.invoke(app, [*args, "--force"])
    assert forced.exit_code == 0, forced.output
    assert json.loads(js.read_text())["scenario"] == "ice" and png.stat().st_size > 10_000
    twice = runner.invoke(app, ["ice", "--duration", "0.05", "--json", str(tmp_path / "a"), "--csv", str(tmp_path / "a")])
    assert twice.exit_code == 2 and not (tmp_path / "a").exists()


def test_a_failure_the_run_never_reaches_is_refused():
    res = runner.invoke(app, ["ice", "--failure", "seed", "--duration", "0.05", "--no-noise"])
    assert res.exit_code == 2 and "nothing was injected" in res.stderr  # the seed's failure is at 20 s


def test_command_line_of_a_nominal_failure2_run_says_so():
    assert command_line("harv_latdir_failure2", failure=None) == "alloc sim harv_latdir_failure2 --failure none"
    assert command_line("ice", failure=None) == "alloc sim ice"


def test_list_names_every_scenario_and_failure():
    res = runner.invoke(app, ["--list"])
    assert res.exit_code == 0, res.output
    assert "harv_latdir_failure2:" in res.stdout and "failure failure2" in res.stdout
    assert "--failure seed:" in res.stdout


def test_vehicle_names_its_scenario():
    """``--vehicle`` takes a scenario's name or a catalogue vehicle whose alias is one (harv: harv_latdir)."""
    res = runner.invoke(app, ["--vehicle", "harv", "--duration", "0.1", "--no-noise", "--method", "daisy"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)
    assert summary["scenario"] == "harv_latdir" and summary["method"] == "daisy" and summary["allocator_calls"] == 201
    # a vehicle with a model but no scenario flies its model with the section 4.3 auto-design (sim.user_vehicle)
    res = runner.invoke(app, ["--vehicle", "ice-design", "--duration", "0.1", "--no-noise"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["settings"]["design"]["procedure"] == "seed section 4.3"
