"""The benchmarks' header line names the machine it was measured on."""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                "scripts"))
import _bench  # noqa: E402


def test_cpu_name_tells_two_epycs_apart():
    zen4 = {"model name": "AMD EPYC", "cpu family": "25", "model": "17"}
    zen5 = {"model name": "AMD EPYC", "cpu family": "26", "model": "2"}
    assert _bench.cpu_name(zen4) == "AMD EPYC (family 25, model 17)"
    assert _bench.cpu_name(zen5) == "AMD EPYC (family 26, model 2)"
    assert _bench.cpu_name({"model name": "Some CPU"}) == "Some CPU (family ?, model ?)"
    assert _bench.cpu_name({}) == "unknown CPU"


def test_blas_line_starts_with_this_cpu_and_names_numpy():
    line = _bench.blas_line()
    assert line.startswith(_bench.cpu_name(_bench.cpu_fields()) + "; ")
    assert f"NumPy {np.__version__}, OpenBLAS kernels " in line


def test_cpu_fields_reads_the_first_processor_only():
    fields = _bench.cpu_fields()
    if not os.path.exists("/proc/cpuinfo"):
        assert fields == {}
        return
    with open("/proc/cpuinfo") as fh:
        first = fh.read().split("\n\n")[0]
    assert fields.get("processor") == "0"
    assert set(fields) == {row.partition(":")[0].strip() for row in first.splitlines()}
