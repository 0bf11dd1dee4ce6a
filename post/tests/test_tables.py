"""Tests of the table reader and the anm-post table command."""
import pytest

from anm_post import AnmPostError, read_geometry_table
from anm_post.cli import main

HEADER = "Name volume surf._area L/T W/T\n"


def test_reads_columns(tmp_path):
    p = tmp_path / "g.txt"
    p.write_text(HEADER + "a.dat 1.0 2.0 2.0 1.5\nb.dat 3.0 4.0 3.0 2.5\n")
    t = read_geometry_table(str(p))
    assert t.names == ["a.dat", "b.dat"]
    assert t.column("volume").tolist() == [1.0, 3.0]
    assert t.summary()["L/T"][0] == pytest.approx(2.5)
    assert "a.dat,1,2,2,1.5" in t.to_csv()


@pytest.mark.parametrize(
    "body, fragment",
    [
        ("a.dat 1.0 2.0 2.0\n", ":2: expected 5 fields"),
        ("a.dat 1.0 x 2.0 1.5\n", ":2: non-numeric value 'x'"),
        ("", "no rows"),
    ],
)
def test_bad_tables_name_file_and_line(tmp_path, body, fragment):
    p = tmp_path / "bad.txt"
    p.write_text(HEADER + body)
    with pytest.raises(AnmPostError) as exc:
        read_geometry_table(str(p))
    assert str(p) in str(exc.value) and fragment in str(exc.value)


def test_cli_error_is_a_message_not_a_traceback(tmp_path, capsys):
    rc = main(["table", str(tmp_path / "missing.txt")])
    assert rc == 1
    err = capsys.readouterr().err
    assert "missing.txt" in err and "Traceback" not in err


def test_nist_table_with_stray_bytes(shapes_dir):
    t = read_geometry_table(str(shapes_dir / "MA107-6-fine" / "MA107-6-fine-geom.dat"))
    assert len(t) == 666
    # identities stated by the data: L/T = length / thick
    assert t.column("L/T") == pytest.approx(t.column("length(mm)") / t.column("thick(mm)"), rel=2e-3)
