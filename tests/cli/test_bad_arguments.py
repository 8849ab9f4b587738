"""Arguments the batch cannot use end it at once with exit status 2 and one
line saying why, before any file is read (found by a fuzz of the batch CLI on
2026-12-05: a NaN or infinite --max-error and a --feature-angle outside (0,
180] failed every file one by one, exit 1; a --dask address that names no
scheduler ended in distributed's traceback). --timeout takes a positive,
finite number of seconds."""

import pytest

import core
from tests.cli.test_batch import run_batch
from tests.mesh_factory import icosphere


@pytest.mark.parametrize("args, said", [
    (["--max-error", "nan"], "--max-error must be a positive number"),
    (["--max-error", "inf"], "--max-error must be a positive number"),
    (["--faces", "40", "--feature-angle", "nan"], "--feature-angle must be in (0, 180] degrees"),
    (["--faces", "40", "--feature-angle", "-5"], "--feature-angle must be in (0, 180] degrees"),
    (["--faces", "40", "--feature-angle", "1e9"], "--feature-angle must be in (0, 180] degrees"),
    (["--faces", "40", "--timeout", "0"],
     "--timeout must be a positive number of seconds, got 0"),
    (["--faces", "40", "--timeout", "-3"],
     "--timeout must be a positive number of seconds, got -3"),
    (["--faces", "40", "--timeout", "nan"],
     "--timeout must be a positive number of seconds, got nan"),
    (["--faces", "40", "--timeout", "inf"],
     "--timeout must be a positive number of seconds, got inf"),
    (["--faces", "40", "--timeout", "30s"], "argument --timeout: invalid float value: '30s'"),
    (["--faces", "1000", "--refine", "99"], "--refine: levels=99 would make 4.02e+62 faces of "
                                            "1,000 (each level multiplies them by 4)"),
    (["--ratio", "0.5", "--refine", "15"], "--refine: levels=15 would make 4.29e+09 faces of 4"),
])
def test_a_number_the_batch_cannot_use_is_a_bad_argument(tmp_path, args, said):
    core.write_obj(tmp_path / "ball.obj", *icosphere(2))
    proc = run_batch(["ball.obj", "--out", "out", *args], tmp_path)
    assert proc.returncode == 2 and said in proc.stderr, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr and not (tmp_path / "out" / "ball_cage.obj").exists()


def test_a_dask_address_that_names_no_scheduler_is_said_without_a_traceback(tmp_path):
    pytest.importorskip("distributed")
    core.write_obj(tmp_path / "ball.obj", *icosphere(2))
    proc = run_batch(["ball.obj", "--faces", "40", "--out", "out", "--dask", "nonsense://x"],
                     tmp_path)
    assert proc.returncode == 2, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    assert ("--dask: cannot reach the Dask scheduler nonsense://x: unknown address scheme "
            "'nonsense'") in proc.stderr
