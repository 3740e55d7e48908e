"""The state folder (``controller.paths.state_dir``): one sub-folder per taught part.

Each part's teach-in, datasets and models lie side by side in the folder named after it::

    state/cube/cell.json  state/cube/datasets/nn1.npz  state/cube/model-gabor.fpm
    state/nut/cell.json   state/nut/datasets/nn1.npz   state/nut/model-gabor.fpm

A folder written before parts had folders of their own holds one part at its top
(``state/cell.json``, ``state/datasets/``, ``state/model-*``); it is read as the part its
``cell.json`` records (or the configured part, when that file cannot be read), in place, and a
new teach-in of that part writes there again. Other parts taught later get their own folder
beside it. To move such a folder to the per-part layout, move its files into a folder named
after the part: ``mkdir state/cube && mv state/cell.json state/datasets state/model-*
state/cube/``.
"""

from __future__ import annotations

from pathlib import Path

from drivers.core import parts
from drivers.core.cell_state import CellState, StateError
from drivers.core.errors import ConfigError

STATE_FILE = "cell.json"


class StateFolder:
    """Where each part's files live under the state folder ``root``.

    Args:
        root: the state folder (``controller.paths.state_dir`` or ``--state-dir``).
        configured_part: the part a single-part folder holds when its ``cell.json`` cannot be
            read (the configured part, ``controller.part``, or the simulated table's).
        catalogue: the parts the cell knows (the config's ``parts``; default: the built-in
            ones).
    """

    def __init__(self, root: str | Path, configured_part: str,
                 catalogue: parts.Catalogue = parts.PARTS) -> None:
        self.root = Path(root)
        self.configured_part = configured_part
        self.catalogue = catalogue

    def single_part(self) -> str | None:
        """The part of a single-part folder (``cell.json`` at the top), or None without one."""
        path = self.root / STATE_FILE
        if not path.exists():
            return None
        try:
            kind = CellState.load(path).object_kind
        except StateError:
            return self.configured_part
        return kind if kind in self.catalogue else self.configured_part

    def part_dir(self, kind: str) -> Path:
        """The folder of part ``kind``'s teach-in, datasets and models (which need not exist
        yet): ``root/<kind>``, or ``root`` itself when it is a single-part folder of that part
        and ``root/<kind>`` holds no teach-in."""
        self.catalogue.check(kind)
        own = self.root / kind
        if not (own / STATE_FILE).exists() and self.single_part() == kind:
            return self.root
        return own

    def taught(self) -> dict[str, Path]:
        """The taught parts (those with a ``cell.json``) and their folders, in catalogue order."""
        single = self.single_part()
        return {kind: (self.root / kind if (self.root / kind / STATE_FILE).exists()
                       else self.root)
                for kind in self.catalogue
                if (self.root / kind / STATE_FILE).exists() or kind == single}

    def resolve(self, requested: str | None, default: str) -> str:
        """The part a command works on: ``requested`` (checked against the catalogue); else
        the one taught part; else ``default`` (the cell's part) when nothing is taught.

        Raises:
            ConfigError: an unknown part, or several parts taught and none named.
        """
        if requested is not None:
            return self.catalogue.check(requested)
        taught = list(self.taught())
        if len(taught) == 1:
            return taught[0]
        if len(taught) > 1:
            raise ConfigError(f"{self.root}: several parts are taught ({', '.join(taught)}); "
                              "name one with --part")
        return self.catalogue.check(default)

    def folders(self) -> list[Path]:
        """Every folder the state is written into (for the clean-up of interrupted writes):
        the root, each taught part's folder and their ``datasets`` folders."""
        found = [self.root, self.root / "datasets"]
        for folder in self.taught().values():
            found += [folder, folder / "datasets"]
        return list(dict.fromkeys(found))
