"""Holds N slowloris connections to a server until killed: each sends half a request head and then
nothing; one the server closes (at its head deadline, or refused) is opened again at once, as a
real attacker's would be. Connections come from 127.0.1.x, 125 per address. Prints "ready" once
all are open, and on SIGTERM how many were reopened."""

import selectors
import signal
import socket
import sys

HALF_HEAD = b"GET / HTTP/1.1\r\nHost: slowloris\r\nX-a: "


def main():
    port, count = int(sys.argv[1]), int(sys.argv[2])
    selector = selectors.DefaultSelector()
    reopened = [0]

    def open_one(i):
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.bind((f"127.0.1.{1 + i // 125}", 0))
        s.connect(("127.0.0.1", port))
        s.sendall(HALF_HEAD)
        s.setblocking(False)
        selector.register(s, selectors.EVENT_READ, i)

    for i in range(count):
        open_one(i)
    print("ready", flush=True)
    stop = [False]
    signal.signal(signal.SIGTERM, lambda *_: stop.__setitem__(0, True))
    while not stop[0]:
        for key, _ in selector.select(timeout=0.2):
            s = key.fileobj
            try:
                data = s.recv(65536)
            except OSError:
                data = b""
            if not data:  # closed by the server: reopen
                selector.unregister(s)
                s.close()
                reopened[0] += 1
                open_one(key.data)
    print(f"reopened {reopened[0]}", flush=True)


if __name__ == "__main__":
    main()
