"""A TCP middleman between the pilot's ``asctec-ll://`` airframe and an LL board's TCP line,
for the tests of a line that misbehaves: it can add garbage, drop what the board says (a
silent board), spoil one frame of the board's (a subclass's ``from_board``), or be cut."""

from __future__ import annotations

import random
import socket
import threading

from skeye.workers import Worker


class Proxy:
    """Pipes both ways between a client and the board's line at ``port``: ``garbage`` puts
    random bytes before 30 % of the chunks, ``silent`` drops what the board sends, and
    :meth:`from_board` may change the board's chunks before they go on."""

    def __init__(self, port: int) -> None:
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port = self.listener.getsockname()[1]
        self.target = port
        self.garbage = False
        self.silent = False
        self.injected = 0
        self.rng = random.Random(7)
        self.socks: list[socket.socket] = []
        self.stop = threading.Event()
        self.workers = [Worker(self._accept, "test-proxy-accept").start()]

    def from_board(self, data: bytes) -> bytes:
        """A chunk the board sent, as it goes on to the client (here: unchanged)."""
        return data

    def _accept(self) -> None:
        self.listener.settimeout(0.1)
        while not self.stop.is_set():
            try:
                a, _ = self.listener.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            b = socket.create_connection(("127.0.0.1", self.target))
            self.socks += [a, b]
            self.workers.append(Worker(self._pipe, "test-proxy-up", args=(a, b, False)).start())
            self.workers.append(Worker(self._pipe, "test-proxy-down", args=(b, a, True)).start())

    def _pipe(self, src: socket.socket, dst: socket.socket, from_board: bool) -> None:
        src.settimeout(0.1)
        while not self.stop.is_set():
            try:
                data = src.recv(4096)
            except TimeoutError:
                continue
            except OSError:
                return
            if not data:
                return
            if from_board:
                if self.silent:
                    continue
                data = self.from_board(data)
            if self.garbage and self.rng.random() < 0.3:
                junk = bytes(self.rng.randrange(256) for _ in range(self.rng.randrange(1, 40)))
                self.injected += len(junk)
                data = junk + data
            try:
                dst.sendall(data)
            except OSError:
                return

    def close(self) -> None:
        self.stop.set()
        self.listener.close()
        for s in self.socks:
            s.close()
        for w in self.workers:
            w.join(2.0)
