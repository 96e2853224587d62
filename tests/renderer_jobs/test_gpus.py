"""Which GPUs local workers use and how they are dealt (renderer_jobs.gpus)."""

from __future__ import annotations

import os

import pytest

from renderer_jobs.gpus import visible_gpus, worker_slots


@pytest.mark.parametrize("cvd, want", [("0,1,2", ["0", "1", "2"]), ("2", ["2"]), ("", []), ("-1", []),
                                       ("1,-1,3", ["1"]), (" 0 , 1 ", ["0", "1"]),
                                       ("GPU-5f0b1c2a", ["GPU-5f0b1c2a"])])
def test_cuda_visible_devices_decides_when_set(cvd, want):
    assert visible_gpus({"CUDA_VISIBLE_DEVICES": cvd, "PATH": ""}) == want


def test_nvidia_smi_lists_the_gpus_otherwise(tmp_path):
    smi = tmp_path / "nvidia-smi"
    smi.write_text("#!/bin/sh\nprintf '0\\n1\\n'\n")
    smi.chmod(0o755)
    assert visible_gpus({"PATH": str(tmp_path)}) == ["0", "1"]
    smi.write_text("#!/bin/sh\necho 'NVIDIA-SMI has failed' >&2; exit 9\n")
    assert visible_gpus({"PATH": str(tmp_path)}) == []
    assert visible_gpus({"PATH": str(tmp_path / "nowhere")}) == []


@pytest.mark.parametrize("workers, gpus, want", [
    (None, ["0", "1"], ["0", "1"]),  # one per GPU by default
    (None, [], [None]),  # no GPU: one CPU worker
    (3, [], [None, None, None]),
    (4, ["0", "1"], ["0", "1", "0", "1"]),  # more workers than GPUs: dealt round-robin
    (1, ["0", "1", "2"], ["0"]),
    (None, ["3"], ["3"]),
])
def test_worker_slots(workers, gpus, want):
    assert worker_slots(workers, gpus) == want


def test_worker_slots_refuses_zero():
    with pytest.raises(ValueError):
        worker_slots(0, ["0"])


def test_this_machine_reports_a_list():
    assert isinstance(visible_gpus(dict(os.environ)), list)
