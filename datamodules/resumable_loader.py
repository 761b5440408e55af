"""A graph DataLoader whose shuffled position survives a checkpoint."""

from __future__ import annotations

from typing import Iterator

import torch
from torch.utils.data import Dataset, Sampler
from torch_geometric.loader import DataLoader as GraphLoader


class EpochPermutation(Sampler[int]):
    """A random order drawn from ``(seed, epoch)`` alone, which can start
    part-way through. Lightning calls :meth:`set_epoch` before every epoch, as
    for :class:`~torch.utils.data.DistributedSampler`."""

    def __init__(self, size: int, seed: int = 0):
        self.size, self.seed = size, seed
        self.epoch, self.skip = 0, 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def __len__(self) -> int:
        return self.size

    def __iter__(self) -> Iterator[int]:
        generator = torch.Generator().manual_seed(self.seed * 1_000_003 + self.epoch)
        order = torch.randperm(self.size, generator=generator)[self.skip:].tolist()
        self.skip = 0
        return iter(order)


class ResumableGraphLoader(GraphLoader):
    """:class:`torch_geometric.loader.DataLoader` with ``state_dict`` /
    ``load_state_dict``: Lightning stores the batches consumed in the current
    epoch with every checkpoint, and a resumed run continues with the batch the
    interrupted run would have seen next. Batches are counted where they are
    consumed, so the count is exact with worker processes too."""

    def __init__(self, dataset: Dataset, batch_size: int, seed: int = 0, **kwargs):
        self.order = EpochPermutation(len(dataset), seed)
        self._consumed = 0
        super().__init__(dataset, batch_size=batch_size, sampler=self.order, **kwargs)

    def __iter__(self):
        consumed = self._consumed
        for batch in super().__iter__():
            consumed += 1
            self._consumed = consumed
            yield batch
        self._consumed = 0

    def state_dict(self) -> dict[str, int]:
        return {"epoch": self.order.epoch, "batches": self._consumed}

    def load_state_dict(self, state: dict[str, int]) -> None:
        self.order.set_epoch(state["epoch"])
        self.order.skip = state["batches"] * self.batch_size
        self._consumed = state["batches"]
