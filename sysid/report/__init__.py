"""Accuracy reports (HTML and PDF) of a run, a reproduction or preprocessing output.

`build_report(source_dir, out_dir)` reads the directory (`source`), builds the tables
(`tables`, from `sysid.protocol.paper`), plans and draws the figures (`plan`, `figures`), and writes
``report.html`` (`html`) and ``report.pdf`` (`pdf`); `build` runs those steps in order.
"""
from sysid.report.build import ReportPaths, build_report

__all__ = ["ReportPaths", "build_report"]
