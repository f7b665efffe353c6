"""The wire layer: every protocol skeye speaks, sans-IO.

Typed messages (frozen dataclasses) and codecs as tables, one module per protocol, shared by the
servers and the clients. Imports only the standard library, numpy and :mod:`skeye.errors`: no
sockets, no threads, no simulator.
"""
