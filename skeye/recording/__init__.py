"""Recordings of simulator sessions and the tools that read them.

:mod:`skeye.recording.records` writes and reads a recording (every line both ways, plus truth
and notes); :mod:`skeye.recording.replay` serves one again on a control port;
:mod:`skeye.recording.plotting` draws one; :mod:`skeye.recording.snapshot` saves a camera frame
from a running simulator. None of them runs a simulator: they are clients and files only.
"""
