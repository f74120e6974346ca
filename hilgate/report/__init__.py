"""``hilgate report``: figures and tables of traces and summaries."""

from .figures import report
from .tracedata import ReportError, load_trace, pick_run, trace_runs

__all__ = ["ReportError", "load_trace", "pick_run", "report", "trace_runs"]
