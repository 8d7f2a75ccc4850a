"""nodes/start.run_main: a Ctrl-C that a late import turned into another error still ends
the program quietly with its interrupted code; any other error is left alone."""

from __future__ import annotations

import signal
import sys
import time
import types

import pytest

from estimation_nodes.nodes.start import caused_by_interrupt, run_main


def chained_import_error() -> ImportError:
    """What rpyutils' loader raises when a Ctrl-C lands in the middle of rclpy's import."""
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as interrupt:
            raise ImportError("initialization failed") from interrupt
    except ImportError as error:
        return error


def test_an_error_raised_while_handling_a_ctrl_c_is_caused_by_it():
    assert caused_by_interrupt(KeyboardInterrupt())
    assert caused_by_interrupt(chained_import_error())
    try:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise RuntimeError("in a finalizer") from None   # context kept, cause cleared
    except RuntimeError as error:
        # `from None` hides the context from the traceback, not from the chain.
        assert caused_by_interrupt(error)
    assert not caused_by_interrupt(ImportError("no module named x"))
    assert not caused_by_interrupt(ValueError("bad"))


@pytest.fixture
def fake_program(monkeypatch):
    """A module named ``fake_program`` whose main() raises what the test gives it."""
    module = types.ModuleType("fake_program")
    monkeypatch.setitem(sys.modules, "fake_program", module)
    monkeypatch.setattr(sys, "unraisablehook", sys.unraisablehook)   # run_main sets it
    previous = signal.getsignal(signal.SIGINT)
    yield module
    signal.signal(signal.SIGINT, previous)


def test_a_ctrl_c_turned_into_an_import_error_exits_with_the_interrupted_code(fake_program):
    def main():
        raise chained_import_error()

    fake_program.main = main
    with pytest.raises(SystemExit) as ended:
        run_main("fake_program", 130)
    assert ended.value.code == 130
    # The end has begun: a second Ctrl-C is ignored.
    assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN


def test_another_error_is_raised_as_it_is(fake_program):
    def main():
        raise ImportError("no module named missing")

    fake_program.main = main
    with pytest.raises(ImportError, match="missing"):
        run_main("fake_program", 130)


def test_the_programs_own_exit_code_is_kept_after_its_ctrl_c_handling(fake_program):
    def main():
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            sys.exit(7)     # its context is the Ctrl-C; still the program's own exit

    fake_program.main = main
    with pytest.raises(SystemExit) as ended:
        run_main("fake_program", 130)
    assert ended.value.code == 7


def test_a_ctrl_c_swallowed_by_a_finalizer_reaches_the_program(fake_program, capsys):
    # Python prints an "Exception ignored in" traceback for an exception out of a __del__
    # (rclpy's RcutilsLogger.__del__ under a demo's Ctrl-C) and goes on as if nothing
    # happened; run_main gives the Ctrl-C back to the program instead.
    class Finalized:
        def __del__(self):
            raise KeyboardInterrupt

    def main():
        try:
            Finalized()                 # dropped at once: its __del__ is interrupted
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline:     # the Ctrl-C given back arrives here
                pass
        except KeyboardInterrupt:
            sys.exit(42)
        sys.exit(0)

    fake_program.main = main
    with pytest.raises(SystemExit) as ended:
        run_main("fake_program", 130)
    assert ended.value.code == 42
    assert "Exception ignored" not in capsys.readouterr().err


def test_a_node_the_demo_starts_imports_the_demos_package_not_the_current_folders(
        tmp_path, monkeypatch):
    """A folder holding another estimation_nodes (a source checkout, a user's copy): the
    demo's node runs the package the demo runs, not that one (``python -m`` would put the
    current folder first on its path)."""
    from estimation_nodes.tools.demo.graph_runtime import start_node

    fake = tmp_path / "estimation_nodes" / "nodes"
    fake.mkdir(parents=True)
    (tmp_path / "estimation_nodes" / "__init__.py").write_text("")
    (fake / "__init__.py").write_text("")
    marker = tmp_path / "the_folders_package_ran"
    (fake / "start.py").write_text(f"open({str(marker)!r}, 'w').close()\n")
    monkeypatch.chdir(tmp_path)
    # An unknown node: the package's start.py refuses it (exit 2); the folder's would run.
    process = start_node("no_such_node", tmp_path / "params.yaml")
    assert process.wait(timeout=60) == 2
    assert not marker.exists()
