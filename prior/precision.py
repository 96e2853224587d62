"""Whether bf16 autocast is on: ``train.bf16`` / ``finetune.bf16`` = ``true``, ``false`` or
``auto`` (the default).

``auto`` turns it on where the device computes bf16 natively, which is where it is faster:
a CUDA GPU of compute capability 8.0 or later (Ampere on), or a CPU whose flags include
``avx512_bf16`` or ``amx_bf16`` (x86) or ``bf16`` (Arm) in ``/proc/cpuinfo``. Elsewhere bf16
matmuls are emulated and slower than float32 (docs/prior.md, "Speed"), so ``auto`` is off.
torch's own CPU check (``torch.ops.mkldnn._is_mkldnn_bf16_supported``) is true on any AVX-512
CPU, emulation included, so the flags are read instead.
"""

from __future__ import annotations

from pathlib import Path

import torch

#: CPU flags (``/proc/cpuinfo``) of native bf16 arithmetic: x86 AVX-512 BF16 and AMX, Arm's BF16
CPU_BF16_FLAGS = ("avx512_bf16", "amx_bf16", "bf16")


def cpu_flags(cpuinfo: str | Path = "/proc/cpuinfo") -> set[str]:
    """The CPU's feature flags (x86 ``flags``, Arm ``Features``); empty where unknown."""
    try:
        text = Path(cpuinfo).read_text(errors="replace")
    except OSError:
        return set()
    for line in text.splitlines():
        key, _, value = line.partition(":")
        if key.strip() in ("flags", "Features"):
            return set(value.split())
    return set()


def native_bf16(device: torch.device, cpuinfo: str | Path = "/proc/cpuinfo") -> tuple[bool, str]:
    """Whether ``device`` computes bf16 natively, and why (for the run's log)."""
    if device.type == "cuda":
        major, minor = torch.cuda.get_device_capability(device)
        name = torch.cuda.get_device_name(device)
        ok = major >= 8
        return ok, f"{name}, compute capability {major}.{minor} ({'>=' if ok else '<'} 8.0)"
    if device.type == "cpu":
        found = sorted(cpu_flags(cpuinfo) & set(CPU_BF16_FLAGS))
        if found:
            return True, f"CPU has {', '.join(found)}"
        return False, "CPU has none of " + ", ".join(CPU_BF16_FLAGS)
    return False, f"no native bf16 check for {device.type}"


def resolve_bf16(setting: bool | str, device: torch.device, key: str) -> tuple[bool, str]:
    """``setting`` (true, false or "auto") of config key ``key`` as on/off, and the log line that
    says which was chosen and why."""
    if setting == "auto":
        on, why = native_bf16(device)
        return on, f"{key} = auto: bf16 autocast {'on' if on else 'off'} ({why})"
    on = bool(setting)
    return on, f"{key} = {str(on).lower()}: bf16 autocast {'on' if on else 'off'}"
