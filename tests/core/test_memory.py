"""core._memory: freed blocks kept for reuse inside the context, restored after."""

import importlib
import threading

import numpy as np
import pytest

memory = importlib.import_module("core._memory")


class _FakeLibc:
    def __init__(self):
        self.calls = []

    def mallopt(self, param, value):
        self.calls.append((param, value))
        return 1

    def malloc_trim(self, pad):
        self.calls.append(("trim", pad))
        return 1


def test_thresholds_raised_inside_and_restored_by_the_last_one_out(monkeypatch):
    fake = _FakeLibc()
    monkeypatch.setattr(memory, "_libc", fake)
    with memory.reuse_freed_memory():
        assert fake.calls == [(memory._M_MMAP_THRESHOLD, memory._RUN_MMAP),
                              (memory._M_TRIM_THRESHOLD, memory._RUN_TRIM)]
        with memory.reuse_freed_memory():          # nested: nothing more happens
            pass
        assert len(fake.calls) == 2
    assert fake.calls[2:] == [(memory._M_MMAP_THRESHOLD, memory._MMAP_DEFAULT),
                              (memory._M_TRIM_THRESHOLD, memory._TRIM_DEFAULT), ("trim", 0)]
    assert memory._depth == 0


def test_restored_even_when_the_work_fails(monkeypatch):
    fake = _FakeLibc()
    monkeypatch.setattr(memory, "_libc", fake)
    with pytest.raises(ValueError):
        with memory.reuse_freed_memory():
            raise ValueError("boom")
    assert fake.calls[-1] == ("trim", 0) and memory._depth == 0


def test_concurrent_users_restore_once(monkeypatch):
    fake = _FakeLibc()
    monkeypatch.setattr(memory, "_libc", fake)
    inside = threading.Barrier(4)

    def work():
        with memory.reuse_freed_memory():
            inside.wait()

    threads = [threading.Thread(target=work) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert fake.calls.count(("trim", 0)) == 1 and memory._depth == 0


def test_without_glibc_it_does_nothing(monkeypatch):
    monkeypatch.setattr(memory, "_libc", False)
    with memory.reuse_freed_memory():
        x = np.ones(10)
    assert x.sum() == 10 and memory._depth == 0


def test_real_allocator_still_works_after_the_context():
    # on this (glibc) machine the real calls run; large arrays still allocate and free
    with memory.reuse_freed_memory():
        a = [np.ones(1 << 22) for _ in range(3)]
        del a
    b = np.ones(1 << 22)
    assert b.sum() == float(1 << 22)
