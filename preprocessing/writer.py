"""Writing processed segments and the run report atomically (temp file, then os.replace).

Segment files are ``STEM.csv`` for a single segment, else ``STEM_seg1.csv``, ...; the
report is ``STEM.report.json``. Nothing is left behind when a write fails; files get the
user's umask. (`sysid preprocess` writes into a staged directory, so a rerun leaves no
stale segment of an earlier run.)
"""
from __future__ import annotations

import dataclasses

import os
import uuid
from pathlib import Path

import pandas as pd

from preprocessing import schema
from preprocessing.quality import QualityReport


def _atomic(path: Path, write) -> None:
    # a fresh temporary created with mode 0666: the umask applies, as to any new file
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        with os.fdopen(fd, "w", newline="") as fh:
            write(fh)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def segment_paths(outdir: Path, stem: str, count: int) -> list[Path]:
    """Output CSV paths for `count` segments of run `stem`."""
    if count == 1:
        return [outdir / f"{stem}.csv"]
    return [outdir / f"{stem}_seg{i + 1}.csv" for i in range(count)]


def write_segments(outdir, stem: str, segments: list[pd.DataFrame], report: QualityReport) -> list[Path]:
    """Write the segments (processed-schema header ``name [unit]``) and the JSON report."""
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    paths = segment_paths(outdir, stem, len(segments))
    names = schema.header(schema.PROCESSED)
    done: list[Path] = []
    try:
        for seg, path in zip(segments, paths):
            frame = seg[list(schema.PROCESSED)].copy()
            frame.columns = names
            _atomic(path, lambda fh, f=frame: f.to_csv(fh, index=False))
            done.append(path)
        report = dataclasses.replace(report, outputs=[p.name for p in paths])
        rpath = outdir / f"{stem}.report.json"
        _atomic(rpath, lambda fh: fh.write(report.to_json()))
        done.append(rpath)
    except BaseException:
        for p in done:
            p.unlink(missing_ok=True)
        raise
    return done
