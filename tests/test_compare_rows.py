"""The compare command's rows: every row gets the same budget, whatever its particles/iterations split."""
import pytest

from markerless_mocap.operators.cmd_compare import DEFAULT_ROWS, _parse_row, _rows


def test_default_rows_share_the_budget_and_include_isa_at_half_the_particles():
    rows = _rows(None, 200, 15)
    assert len(rows) == len(DEFAULT_ROWS)
    splits = {row.label: row.split for row in rows}
    assert splits["ISA (s+e)"] is None                        # --particles x --iterations: the paper's 200 x 15
    assert splits["ISA (s+e), 100 x 30"] == (100, 30)
    assert all(s is None or s[0] * s[1] == 3000 for s in splits.values())


def test_a_row_can_name_its_split():
    row = _parse_row("isa+icp:silh+edge@50x60")
    assert (row.algorithm, row.likelihood, row.refine, row.split) == ("isa", "silh+edge", "icp", (50, 60))
    assert row.label == "ISA + ICP refinement (silh+edge), 50 x 60"
    assert _parse_row("apf:silhch+color").split is None


def test_a_row_with_another_budget_is_refused_with_the_fix():
    with pytest.raises(SystemExit, match="same budget.*3000"):
        _rows("isa:silh+edge@100x20", 200, 15)
    with pytest.raises(SystemExit, match="@PARTICLESxITERATIONS"):
        _parse_row("isa:silh+edge@100")
    with pytest.raises(SystemExit, match="even --particles"):
        _rows(None, 25, 4)                                     # 12 x 8 != 25 x 4
