"""``surgsim bench batch`` refuses bad arguments with a clear message (the figures themselves are
measured by the command, never asserted)."""

import pytest

from surgsim_envs.bench.batch_speed import parse_worlds
from surgsim_envs.cli import main
from surgsim_envs.errors import ConfigError


def test_world_counts_are_parsed_and_checked():
    assert parse_worlds("1,256,4096") == [1, 256, 4096]
    with pytest.raises(ConfigError, match=r"--worlds: 'x' is not an integer; give world counts like 1,256,4096"):
        parse_worlds("1,x")
    with pytest.raises(ConfigError, match=r"--worlds: 0 must lie in \[1, "):
        parse_worlds("0")


def test_cli_reports_a_bad_device(capsys):
    pytest.importorskip("warp")
    assert main(["bench", "batch", "--device", "tpu", "--worlds", "1"]) == 2
    assert "device='tpu' must be 'cpu', 'cuda' or 'cuda:<index>'" in capsys.readouterr().err


def test_cli_reports_a_task_without_a_batched_env(capsys):
    pytest.importorskip("warp")
    assert main(["bench", "batch", "--task", "SurgSim/PalpationPress-v0", "--worlds", "1"]) == 2
    assert "--task 'SurgSim/PalpationPress-v0' has no batched env; choose one of ['SurgSim/Grasp-v0'" in capsys.readouterr().err


def test_cli_reports_bad_outputs(capsys, monkeypatch):
    pytest.importorskip("warp")
    assert main(["bench", "batch", "--outputs", "host,gpu", "--worlds", "1"]) == 2
    assert "--outputs: 'gpu' is not one of ['host', 'device']; give e.g. host,device" in capsys.readouterr().err
    assert main(["bench", "batch", "--outputs", "device,", "--worlds", "1"]) == 2
    assert "--outputs: '' is not one of ['host', 'device']" in capsys.readouterr().err
    # every batched task has device outputs; a task env without them is refused with the list of those that do
    from surgsim_envs.batch.slippage_env import BatchedSlippageEnv

    monkeypatch.setattr(BatchedSlippageEnv, "DEVICE_OUTPUTS", False)
    assert main(["bench", "batch", "--task", "SurgSim/Slippage-v0", "--outputs", "device", "--worlds", "1"]) == 2
    err = capsys.readouterr().err
    assert "--outputs device: SurgSim/Slippage-v0's batched env computes its observations and rewards on the host" \
        in err
    assert ("only SurgSim/Palpation-v0, SurgSim/Grasp-v0 and SurgSim/Slippage-v0 have device outputs. Use --outputs "
            "host") in err


def test_cli_reports_graphs_where_they_cannot_be_captured(capsys):
    pytest.importorskip("warp")
    assert main(["bench", "batch", "--graphs", "on", "--worlds", "1"]) == 2
    assert "graphs='on' on device cpu: Warp's CPU device cannot capture graphs; use graphs='auto' or 'off'" \
        in capsys.readouterr().err
