import pytest
import torch

# Two threads on a busy 2-core machine can be 10x slower than one.
torch.set_num_threads(1)


@pytest.fixture(autouse=True)
def _seed():
    torch.manual_seed(12345)
