"""The models in use by the service's positioning jobs, one slot per taught part, and what
``status`` says about them."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

from controller.fine_positioner import FinePositioner
from controller.systems.base import TrainedModel

DEFAULT_SYSTEM = "gabor"


class ModelSlot:
    """The model the positioning loop uses for one part, and what status reports about it
    (thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._model: TrainedModel | None = None
        self._info: dict[str, Any] | None = None

    @property
    def model(self) -> TrainedModel | None:
        """The model in use, or None before one was set or loaded."""
        return self._model

    def info(self) -> dict[str, Any] | None:
        """A copy of what ``status`` reports about the model in use, or None without one."""
        with self._lock:
            return dict(self._info) if self._info else None

    def marker(self) -> object:
        """An object that is replaced whenever another model is put into use."""
        return self._info

    def set(self, model: TrainedModel, path: Path) -> None:
        """Put ``model`` into use; ``path`` is its file, reported by ``info`` with the time."""
        with self._lock:
            self._model = model
            self._info = {"system": model.system, "file": str(path),
                          "train_images": model.train_images,
                          "feature_count": model.feature_count, "loaded_at": time.time()}

    def load(self, fp: FinePositioner, system: str) -> TrainedModel:
        """Load ``system``'s model from the state folder into use (the old one stays on error)."""
        model = fp.load_model(system=system)
        self.set(model, fp.model_path(system))
        return model

    def require(self, fp: FinePositioner) -> TrainedModel:
        """The model in use, loading the default system's on first need."""
        return self._model or self.load(fp, DEFAULT_SYSTEM)


class PartModels:
    """One ModelSlot per part, each kept loaded once set (thread-safe): positioning another
    part needs no reload."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._slots: dict[str, ModelSlot] = {}

    def slot(self, part: str) -> ModelSlot:
        """The slot of ``part`` (a new, empty one the first time)."""
        with self._lock:
            return self._slots.setdefault(part, ModelSlot())

    def info(self, part: str) -> dict[str, Any] | None:
        """What ``status`` reports about ``part``'s model, or None without one."""
        with self._lock:
            slot = self._slots.get(part)
        return slot.info() if slot is not None else None

    def infos(self) -> dict[str, dict[str, Any] | None]:
        """What ``status`` reports about each part's model ({part: info or None})."""
        with self._lock:
            slots = dict(self._slots)
        return {part: slot.info() for part, slot in slots.items()}

    def marker(self) -> tuple:
        """An object that changes whenever any part's model is replaced."""
        with self._lock:
            return tuple((part, slot.marker()) for part, slot in self._slots.items())
