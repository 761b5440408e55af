"""A graph DataLoader whose shuffled position survives a checkpoint, sharded
across the processes of a distributed run."""

from __future__ import annotations

import math
from typing import Iterator

import torch
from torch.utils.data import Dataset, DistributedSampler
from torch_geometric.loader import DataLoader as GraphLoader


class EpochPermutation(DistributedSampler):
    """A random order drawn from ``(seed, epoch)`` alone, which can start
    part-way through. Lightning calls :meth:`set_epoch` before every epoch.

    With ``num_replicas`` processes, process ``rank`` takes every
    ``num_replicas``-th index of the order from position ``rank``; the order is
    padded with its own start to a multiple of ``num_replicas`` so that every
    process draws as many samples (as :class:`~torch.utils.data.DistributedSampler`,
    which this is, so Lightning does not wrap it again)."""

    def __init__(self, dataset: Dataset, seed: int = 0, num_replicas: int = 1, rank: int = 0):
        if not 0 <= rank < num_replicas:
            raise ValueError(f"rank {rank} is outside the {num_replicas} processes")
        super().__init__(dataset, num_replicas=num_replicas, rank=rank, shuffle=True, seed=seed)
        self.skip = 0

    def __iter__(self) -> Iterator[int]:
        generator = torch.Generator().manual_seed(self.seed * 1_000_003 + self.epoch)
        order = torch.randperm(len(self.dataset), generator=generator)
        order = order.repeat(math.ceil(self.total_size / max(len(order), 1)))[:self.total_size]
        shard = order[self.rank::self.num_replicas][self.skip:].tolist()
        self.skip = 0
        return iter(shard)


class ResumableGraphLoader(GraphLoader):
    """:class:`torch_geometric.loader.DataLoader` with ``state_dict`` /
    ``load_state_dict``: Lightning stores the batches consumed in the current
    epoch with every checkpoint, and a resumed run continues with the batch the
    interrupted run would have seen next. Batches are counted where they are
    consumed, so the count is exact with worker processes too. In a distributed
    run each process loads its own shard (:class:`EpochPermutation`) and counts
    its own batches; all shards have the same length."""

    def __init__(self, dataset: Dataset, batch_size: int, seed: int = 0, num_replicas: int = 1,
                 rank: int = 0, **kwargs):
        self.order = EpochPermutation(dataset, seed, num_replicas, rank)
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
