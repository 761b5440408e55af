"""A callback for the distributed-training test: every process appends the
windows of each batch it trains on to ``<folder>/rank<r>.jsonl``."""

import json
from pathlib import Path

import lightning as L


class RecordWindows(L.Callback):
    def __init__(self, folder: str):
        self.folder = Path(folder)

    def on_train_batch_start(self, trainer, module, batch, batch_index: int) -> None:
        windows = [f"{sequence}:{frame}" for sequence, frame in
                   zip(batch.sequence, batch.frame.tolist())]
        with open(self.folder / f"rank{trainer.global_rank}.jsonl", "a") as log:
            log.write(json.dumps({"step": trainer.global_step, "windows": windows}) + "\n")
