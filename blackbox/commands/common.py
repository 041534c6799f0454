"""What every command does first: read the study, pick its adapter."""

from __future__ import annotations

from pathlib import Path

from blackbox.adapters import make_adapter_for
from blackbox.study import Study, load_study
from solver_adapters.protocol import SolverAdapter

__all__ = ["as_study", "study_adapter"]


def as_study(study: Study | str | Path, *, need_measurements: bool = False) -> Study:
    """A loaded study, from a :class:`Study` or its folder."""
    if isinstance(study, Study):
        if need_measurements and study.measurements is None:
            from blackbox.errors import StudyError
            raise StudyError("measurements.csv not found (needed for this command)", file=str(study.root))
        return study
    return load_study(study, need_measurements=need_measurements)


def study_adapter(study: Study, adapter: str | SolverAdapter | None = None, **kwargs) -> SolverAdapter:
    """``adapter`` itself when it is an adapter, else the study's adapter (or the one named)."""
    if adapter is not None and not isinstance(adapter, str):
        return adapter
    return make_adapter_for(study, adapter, **kwargs)


def copy_study(study: Study, dst: Path, *, skip: tuple[str, ...] = ()) -> list[str]:
    """Copy the study's own files into the existing folder ``dst``; return their relative names.

    Never follows a symbolic link out of the study: a link to a file inside the study is copied
    as that file, a link leading outside it is left out. The run cache and the top-level names in
    ``skip`` are left out too. A deck that lives outside the study folder is not copied; the
    copy's ``study.toml`` then names it by its absolute path."""
    import json
    import os
    import shutil

    root = study.root.resolve()
    dst = Path(dst)
    written: list[str] = []
    for folder, dirs, files in os.walk(root, followlinks=False):
        rel_folder = Path(folder).relative_to(root)
        keep_dirs = []
        for d in dirs:
            p = Path(folder) / d
            if rel_folder == Path(".") and (d in skip or d == ".blackbox_cache"):
                continue
            if p.is_symlink():
                continue                      # a linked folder is never entered
            keep_dirs.append(d)
        dirs[:] = keep_dirs
        for f in files:
            if rel_folder == Path(".") and f in skip:
                continue
            src = Path(folder) / f
            real = src.resolve()
            if not real.is_relative_to(root) or not real.is_file():
                continue
            target = dst / rel_folder / f
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(real, target)
            written.append(str(rel_folder / f))
    deck = study.deck_path.resolve()
    if not deck.is_relative_to(root) or str(Path(study.config.solver.deck)) not in written:
        toml = dst / "study.toml"
        if toml.is_file():
            text = toml.read_text()
            given = study.config.solver.deck
            text = text.replace(json.dumps(given), json.dumps(str(deck))).replace(f"'{given}'", json.dumps(str(deck)))
            toml.write_text(text)
    return written
