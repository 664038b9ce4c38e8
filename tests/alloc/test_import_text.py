"""``alloc.vehicle_file.import_vehicle_text``: a flight stack's file from its text, as ``load_vehicle``
reads the same file, and never taken for a path."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import pytest

from alloc._files import MAX_TEXT_BYTES
from alloc.exceptions import ProblemError, SkippedLinesWarning
from alloc.vehicle_file import IMPORT_FORMATS, import_vehicle_text, load_vehicle

AIRFRAMES = Path(__file__).parent / "data" / "px4_airframes"
TILTROTOR = AIRFRAMES / "13100_generic_vtol_tiltrotor"


def test_each_format_is_load_vehicles_reading_of_the_file(tmp_path):
    (tmp_path / "quad.param").write_text("FRAME_CLASS,1\nFRAME_TYPE,1\nMOT_SLEW_UP_TIME,0.5\n")
    (tmp_path / "tri.csv").write_text("motor,roll,pitch,yaw\nm1,-0.5,0.5,1\nm2,0.5,0.5,-1\nm3,0,-0.5,1\n")
    (tmp_path / "hexa.params").write_text("1\t1\tCA_AIRFRAME\t0\t6\n1\t1\tCA_ROTOR_COUNT\t2\t6\n"
                                          "1\t1\tCA_ROTOR0_PX\t0.2\t9\n1\t1\tCA_ROTOR1_PX\t-0.2\t9\n")
    cases = [(tmp_path / "quad.param", "ardupilot-params"), (tmp_path / "tri.csv", "ardupilot-csv"),
             (tmp_path / "hexa.params", "px4-params"), (TILTROTOR, "px4-airframe")]
    assert {form for _, form in cases} == set(IMPORT_FORMATS)
    for path, form in cases:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            from_file = load_vehicle(path)
        from_text = import_vehicle_text(path.read_text(), form, name=path.stem, label=path.name)
        assert from_text == from_file, path.name  # the schedule and the source's skipped lines too
        # the text entry reports skipped lines in `source` only; the file reader warns as well
        assert [w.category for w in caught] == ([SkippedLinesWarning] if form == "px4-airframe" else [])
    assert "1 shell line(s) skipped (line 12:" in import_vehicle_text(TILTROTOR.read_text(), "px4-airframe").source


def test_a_text_is_never_read_as_a_path(tmp_path):
    secret = tmp_path / "copter.param"
    secret.write_text("FRAME_CLASS,2\n")
    with pytest.raises(ProblemError, match="^params: line 1: expected 'NAME,value'") as info:
        import_vehicle_text(str(secret), "ardupilot-params")
    assert info.value.field == "params"
    with pytest.raises(ProblemError, match="^factors: the CSV header needs columns"):
        import_vehicle_text(str(tmp_path / "frame.csv"), "ardupilot-csv")
    with pytest.raises(ProblemError, match="^params: line 1: expected 'vehicle component NAME value type'"):
        import_vehicle_text(str(TILTROTOR), "px4-params")
    # a CSV body is CSV whatever it contains
    with pytest.raises(ProblemError, match="^factors: the CSV header needs columns"):
        import_vehicle_text('[[motors]]\nname = "a"\nroll = 1\npitch = 0\nyaw = 1\n', "ardupilot-csv")


@pytest.mark.parametrize("text, form, field, message", [
    ("FRAME_CLASS,1\n", "mavlink", "format", ("format: unknown 'mavlink'; flight-stack files are read as one of "
                                             "ardupilot-csv, ardupilot-params, px4-params, px4-airframe")),
    ("1\t1\tCA_AIRFRAME\t0\t6\n", "px4-airframe", "params", "params: the text is not a PX4 airframe file"),
    ("#" * (MAX_TEXT_BYTES + 1), "px4-params", "params", f"params: the text is {MAX_TEXT_BYTES + 1} characters"),
    ("#" * (MAX_TEXT_BYTES + 1), "ardupilot-params", "params", "params: the text is"),
    ("m" * (MAX_TEXT_BYTES + 1), "ardupilot-csv", "factors", "factors: the text is"),
])
def test_refusals_name_the_field(text, form, field, message):
    with pytest.raises(ProblemError, match="^" + re.escape(message)) as info:
        import_vehicle_text(text, form)
    assert info.value.field == field
