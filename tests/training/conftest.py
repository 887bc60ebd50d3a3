"""Shared set-up of the training tests: one torch thread per test process."""

import pytest
import torch


@pytest.fixture(autouse=True)
def _quiet_threads():
    torch.set_num_threads(1)
