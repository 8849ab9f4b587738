"""The batch CLI's report of the lines an OBJ or SMF reader skipped: other
keywords counted per keyword, and lines starting with no keyword (binary
junk, NUL bytes, a line cut short) counted with the first one's number."""

import json

import core
from tests.cli.test_batch import bumpy_sphere, run_batch


def test_skipped_keywords_and_unreadable_lines_are_noted(tmp_path):
    V, F = bumpy_sphere(3)
    core.write_obj(tmp_path / "ball.obj", V, F)
    body = (tmp_path / "ball.obj").read_bytes()
    (tmp_path / "junk.obj").write_bytes(b"vt 0 0\n\x00\x00\x00\nvt 1 0\n\x01\xfe\xff junk\n"
                                        b"1 2 3\nusemtl M\n" + body)
    (tmp_path / "one.smf").write_bytes(body.replace(b"\nv ", b"\n\x00\nv ", 1))
    proc = run_batch(["junk.obj", "one.smf", "ball.obj", "--faces", "200", "--report",
                      "rep.json"], tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    junk, one, ball = json.loads((tmp_path / "rep.json").read_text())["files"]
    assert junk["notes"][:3] == ["skipped 1 'usemtl' line", "skipped 2 'vt' lines",
                                 "skipped 3 unreadable lines (the first is line 2)"]
    assert one["notes"][0] == "skipped 1 unreadable line (line 2)"
    assert not any("skipped" in note for note in ball["notes"])
    assert junk["faces_in"] == one["faces_in"] == ball["faces_in"] == F.shape[0]
    assert junk["status"] == one["status"] == "ok" and junk["faces_out"] == 200
