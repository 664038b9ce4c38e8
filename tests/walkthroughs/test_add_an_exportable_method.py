"""docs/ARCHITECTURE.md "Export it to C", performed: a toy method of the ``affine`` kind is
exported by its own module alone -- one registration declaring the kind and an ``export_data``
returning the kernel's description -- through ``alloc.export.export_c`` and ``alloc export``,
and removed again."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

import alloc
import alloc.export
from alloc import method
from alloc.export_data import AffineData
from alloc.methods.pseudo_inverse import distribution_matrix
from alloc.options import real
from alloc.registry import Method, register


@pytest.fixture
def scratch_registry(monkeypatch):
    """Registrations made in a test disappear after it (built-ins registered first)."""
    alloc.methods()
    monkeypatch.setattr(method, "_REGISTRY", dict(method._REGISTRY))


def _toy_method() -> type[Method]:
    @register("toy_gain", affine=True, export="affine")
    class Gain(Method):
        """Eq 1.23 times a gain: ``u = up + gain P (v - B up)``, clipped."""

        equation = "Eq 1.23 times a gain"
        summary = "toy: the weighted pseudo-inverse times a gain"
        options = {"gain": real(1.0, "scale of the distribution", low=0.0, high=1.0)}

        def __init__(self, problem: alloc.Problem, *, gain: float = 1.0) -> None:
            super().__init__(problem)
            self.P = gain * distribution_matrix(problem)
            self.c = problem.up - self.P @ (problem.B @ problem.up)
            self.fused = (self.c, self.P)

        def solve(self, v, lo, hi, u_prev):
            return self.c + self.P @ v, 0

        def export_data(self) -> AffineData:
            return AffineData(c=self.c, P=self.P)

    return Gain


def _renamed(text: str) -> str:
    return text.replace("toy_gain", "pinv").replace("TOY_GAIN", "PINV")


def test_add_an_exportable_method(scratch_registry, tmp_path):
    _toy_method()
    assert "toy_gain" in alloc.export.EXPORTABLE and alloc.method_info("toy_gain")["export"] == "affine"

    # gain 1 is pinv's map: the same C, name for name (the header's description lines aside)
    toy, pinv = alloc.export.export_c("harv", "toy_gain"), alloc.export.export_c("harv", "pinv")
    assert _renamed(toy.source) == pinv.source
    differ = [a for a, b in zip(_renamed(toy.header).splitlines(), pinv.header.splitlines()) if a != b]
    assert differ and all("Eq 1.23" in line or "pseudo-inverse" in line for line in differ)

    # its option reaches the kernel's map (the safe answer keeps the full Eq 1.23)
    half = alloc.export.export_c("harv", "toy_gain", options={"gain": 0.5})
    P = 0.5 * distribution_matrix(alloc.vehicles.problem("harv"))
    assert "{" + ", ".join(map(repr, P[0].tolist())) + "}" in half.source
    assert "{" + ", ".join(map(repr, P[0].tolist())) + "}" not in toy.source

    # the kind's rules apply to it by name: a closed form takes no iteration cap
    with pytest.raises(alloc.export.ExportError, match="maxit: toy_gain is closed-form"):
        alloc.export.export_c("harv", "toy_gain", maxit=5)

    # the command line lists and writes it
    from alloc.cli import app

    runner = CliRunner()
    assert "toy_gain" in runner.invoke(app, ["export", "--help"], terminal_width=400).output
    out = runner.invoke(app, ["export", "--vehicle", "harv", "--method", "toy_gain", "--out", str(tmp_path)])
    assert out.exit_code == 0, out.output
    assert (tmp_path / "alloc_toy_gain.c").read_text() == toy.source


def test_the_exportable_walkthrough_registry_is_restored():
    assert "toy_gain" not in alloc.methods() and "toy_gain" not in alloc.export.EXPORTABLE
