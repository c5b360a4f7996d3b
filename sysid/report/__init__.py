"""Accuracy reports (HTML and PDF) of a run or a reproduction: `build_report`."""
from sysid.report.base import ReportPaths, build_report, write_report

__all__ = ["ReportPaths", "build_report", "write_report"]
