"""Where the networks and their batches live: ``--device auto|cpu|cuda``.

Networks, sampled batches and observations being decided on go to the device; the replay's
storage and the envs stay on the host. Checkpoints load on any device (the safetensors file
is read on the CPU and copied into the network wherever it is).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import torch

DEVICES: tuple[str, ...] = ("auto", "cpu", "cuda")
"""``auto``: CUDA when this machine has it, else the CPU."""


def resolve_device(name: str | torch.device) -> torch.device:
    """The device ``name`` stands for.

    Raises:
        ValueError: ``name`` is not one of :data:`DEVICES` (a ``cuda:N`` index is accepted),
            or it asks for CUDA on a machine without it.
    """
    import torch  # noqa: PLC0415 - the command lines read DEVICES without loading torch

    if isinstance(name, torch.device):
        name = str(name)
    kind = name.split(":", 1)[0]
    if name not in DEVICES and not (kind == "cuda" and name[5:].isdigit()):
        raise ValueError(f"device must be one of {DEVICES} (or cuda:N), got {name!r}")
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if kind == "cuda" and not torch.cuda.is_available():
        raise ValueError(
            f"device {name!r} asked for, but this machine has no CUDA device (PyTorch sees none); use cpu or auto"
        )
    return torch.device(name)
