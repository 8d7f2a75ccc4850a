"""A Ctrl-C while numba compiles: raised once compiled, never printed and dropped."""

import ctypes
import sys

import pytest

from estimation_nodes.core.compiled_loader import interrupts_held_through_callbacks

CALLBACK = ctypes.CFUNCTYPE(None)


def interrupted_callback() -> None:
    raise KeyboardInterrupt


def failing_callback() -> None:
    raise ValueError("not an interrupt")


def test_an_interrupt_swallowed_by_a_c_callback_is_raised_after_the_block(monkeypatch):
    reported = []
    monkeypatch.setattr(sys, "unraisablehook", reported.append)
    finished = False
    with pytest.raises(KeyboardInterrupt):
        with interrupts_held_through_callbacks():
            CALLBACK(interrupted_callback)()   # as LLVM calls llvmlite's object cache
            finished = True
    assert finished, "the block must run to its end, as the compilation does"
    assert reported == [], "nothing printed"
    assert sys.unraisablehook == reported.append


def test_other_errors_of_a_callback_are_reported_as_before(monkeypatch):
    reported = []
    monkeypatch.setattr(sys, "unraisablehook", reported.append)
    with interrupts_held_through_callbacks():
        CALLBACK(failing_callback)()
    assert [r.exc_type for r in reported] == [ValueError]


def test_without_a_callback_error_nothing_is_raised():
    with interrupts_held_through_callbacks():
        pass
