"""`seqloc serve` keeps answering while slow, idle and hostile clients hold connections (issue 18).

Each case starts a server, sets up the bad clients, times 100 legitimate requests (each on a new
connection, from another client address), then stops the server with SIGTERM while the bad clients
are still connected, and checks that it exits cleanly and promptly:

  slowloris    1,000 connections that each sent half a request head and wait
  idle         2,000 kept-alive connections idle after one answered request
  hostile      a client streaming a 1 GB body, one streaming an endless chunked body and one an
               endless header: each must be cut off by its limit while the server's memory stays
               bounded

The legitimate requests are made once before the bad clients come (the server's first tile reads
and encodings are not what is measured; under ASan they alone take about 100 ms). Passes when
every legitimate request answers 200 with a p99 under 100 ms, the bad connections
were held open (not simply refused) while the requests ran, and the server's exit status is 0.
Loopback only; the bad clients come from other 127.0.0.0/8 addresses than the legitimate one,
spread so that none is over the per-client limit."""

import argparse
import os
import resource
import signal
import socket
import subprocess
import sys
import threading
import time

LEGIT_ADDRESS = "127.0.0.1"
P99_LIMIT_MS = 100.0


def start_server(args, *extra):
    """A server on a free port, warmed up with the legitimate requests."""
    server = subprocess.Popen([args.seqloc, "serve", args.cache, "--port", "0", *extra],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    line = server.stdout.readline()
    if not line.startswith("seqloc serve: http://"):
        server.kill()
        sys.exit(f"the server did not start: {line!r} {server.stderr.read()}")
    port = int(line.split()[2].rstrip("/").rsplit(":", 1)[1])
    region = line.split("(1 region: ")[1].split(")")[0]
    statuses = legit_requests(port, region)[1]
    if any(s != 200 for s in statuses):
        server.kill()
        sys.exit(f"the warm-up requests were not all answered 200: {sorted(set(statuses))}")
    return server, port, region


def connect(port, source):
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    s.bind((source, 0))
    s.settimeout(20)
    s.connect(("127.0.0.1", port))
    return s


def read_response(s):
    """Status and body of one response on a socket (Content-Length framed)."""
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = s.recv(65536)
        if not chunk:
            raise ConnectionError("closed before a response head")
        data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    length = 0
    for line in head.split(b"\r\n")[1:]:
        name, _, value = line.partition(b":")
        if name.strip().lower() == b"content-length":
            length = int(value)
    while len(body) < length:
        chunk = s.recv(65536)
        if not chunk:
            raise ConnectionError("closed inside a response body")
        body += chunk
    return int(head.split()[1]), body[:length]


def legit_requests(port, region, count=100):
    """`count` requests on new connections, /health and tiles in turn: latencies in ms, statuses."""
    latencies, statuses = [], []
    for i in range(count):
        path = "/health" if i % 2 == 0 else f"/regions/{region}/classes/{i % 5}/{i % 3}.png"
        start = time.perf_counter()
        with connect(port, LEGIT_ADDRESS) as s:
            s.sendall(f"GET {path} HTTP/1.1\r\nHost: test\r\nConnection: close\r\n\r\n".encode())
            status, _ = read_response(s)
        latencies.append((time.perf_counter() - start) * 1000.0)
        statuses.append(status)
    return latencies, statuses


def p99(values):
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))]


def still_open(sockets):
    """How many of these sockets the server has not closed (nothing to read, no end of stream)."""
    alive = 0
    for s in sockets:
        s.setblocking(False)
        try:
            alive += 0 if s.recv(1, socket.MSG_PEEK) == b"" else 1  # data would be a bug, counted open
        except BlockingIOError:
            alive += 1
        except OSError:
            pass
        s.setblocking(True)
    return alive


def open_sockets(pid):
    """The sockets a process holds (its listener included)."""
    count = 0
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            count += os.readlink(f"/proc/{pid}/fd/{fd}").startswith("socket:")
        except OSError:
            pass  # closed meanwhile
    return count


def wait_until_accepted(server, count):
    """Waits (at most 30 s) until the server holds `count` connections besides its listener: every
    bad connection accepted, none waiting in the kernel's queue ahead of the timed requests."""
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        if open_sockets(server.pid) >= count + 1:
            return True
        time.sleep(0.01)
    return False


def require_held(label, held, kind, failures):
    """The case is only a case if the server kept every bad connection open while it was timed."""
    alive = still_open(held)
    print(f"  {alive} of {len(held)} {kind} connections still open")
    if alive != len(held):
        failures.append(f"{label}: only {alive} of {len(held)} {kind} connections were held (the case needs them)")


def memory_kb(pid, field):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    raise KeyError(field)


def sigterm_and_wait(server, label, failures):
    start = time.perf_counter()
    server.send_signal(signal.SIGTERM)
    try:
        _, err = server.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        server.kill()
        server.communicate()
        failures.append(f"{label}: the server did not exit within 10 s of SIGTERM")
        return
    seconds = time.perf_counter() - start
    print(f"  SIGTERM: exit {server.returncode} after {seconds:.2f} s; {err.strip().splitlines()[-1]}")
    if server.returncode != 0:
        failures.append(f"{label}: exit status {server.returncode} after SIGTERM: {err}")


def check_legit(label, port, region, failures):
    latencies, statuses = legit_requests(port, region)
    bad = [s for s in statuses if s != 200]
    print(f"  100 legitimate requests: p50 {sorted(latencies)[50]:.2f} ms, p99 {p99(latencies):.2f} ms, "
          f"max {max(latencies):.2f} ms, {len(bad)} not 200")
    if bad:
        failures.append(f"{label}: {len(bad)} legitimate requests were not answered 200: {sorted(set(bad))}")
    if p99(latencies) >= P99_LIMIT_MS:
        failures.append(f"{label}: p99 {p99(latencies):.1f} ms, over {P99_LIMIT_MS} ms")


def bad_addresses(count, per_address):
    """Client addresses 127.0.1.N for `count` connections, `per_address` each."""
    return [f"127.0.1.{1 + i // per_address}" for i in range(count)]


def connections_allowed(wanted):
    """`wanted`, or fewer when this process's open-file limit cannot hold that many sockets (said)."""
    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    allowed = min(wanted, soft - 200)
    if allowed < wanted:
        print(f"  the open-file limit ({soft}) allows {allowed} connections, not {wanted}")
    return allowed


def case_slowloris(args, failures):
    label = "slowloris"
    count = connections_allowed(1000)
    print(f"{label}: {count} connections, each half a request head")
    server, port, region = start_server(args, "--header-timeout", "60")
    held = []
    try:
        for source in bad_addresses(count, 125):
            s = connect(port, source)
            s.sendall(b"GET /health HTTP/1.1\r\nHost: slo")
            held.append(s)
        if not wait_until_accepted(server, count):
            failures.append(f"{label}: the server did not accept the {count} connections within 30 s")
        check_legit(label, port, region, failures)
        require_held(label, held, "slow", failures)
    finally:
        sigterm_and_wait(server, label, failures)
        for s in held:
            s.close()


def case_idle(args, failures):
    label = "idle keep-alive"
    count = connections_allowed(2000)
    print(f"{label}: {count} connections, idle after one answered request")
    server, port, region = start_server(args, "--keep-alive", "60")
    held = []
    try:
        rss_before = memory_kb(server.pid, "VmRSS")
        for source in bad_addresses(count, 125):
            s = connect(port, source)
            s.sendall(b"GET /health HTTP/1.1\r\nHost: idle\r\n\r\n")
            held.append(s)
        for s in held:
            status, _ = read_response(s)
            if status != 200:
                failures.append(f"{label}: an idle client's first request got {status}")
                break
        rss_after = memory_kb(server.pid, "VmRSS")
        print(f"  server memory: {rss_before / 1024:.1f} MiB before, {rss_after / 1024:.1f} MiB with {count} open "
              f"({(rss_after - rss_before) / count:.1f} KiB each)")
        check_legit(label, port, region, failures)
        require_held(label, held, "idle", failures)
    finally:
        sigterm_and_wait(server, label, failures)
        for s in held:
            s.close()


def stream_until_cut(port, source, head, chunk, limit_bytes, result, key):
    """Sends `head`, then `chunk` again and again until the server cuts the connection off or
    `limit_bytes` went out; records the bytes sent, whether it was cut off, and the status read."""
    sent, cut, status = 0, False, None
    try:
        with connect(port, source) as s:
            s.sendall(head)
            while sent < limit_bytes:
                s.sendall(chunk)
                sent += len(chunk)
    except OSError:
        cut = True
    result[key] = (sent, cut, status)


def case_hostile(args, failures):
    label = "hostile"
    print(f"{label}: a 1 GB body, an endless chunked body and an endless header, at full speed")
    server, port, region = start_server(args)
    try:
        hwm_before = memory_kb(server.pid, "VmHWM")
        gib = 1 << 30
        chunk = b"x" * 65536
        cases = {
            "1 GB body": (f"POST /health HTTP/1.1\r\nHost: big\r\nContent-Length: {gib}\r\n\r\n".encode(), chunk),
            "endless chunked body": (b"POST /health HTTP/1.1\r\nHost: big\r\nTransfer-Encoding: chunked\r\n\r\n",
                                     b"10000\r\n" + chunk + b"\r\n"),
            "endless header": (b"GET /health HTTP/1.1\r\nX-Endless: ", chunk),
        }
        result = {}
        threads = [threading.Thread(target=stream_until_cut, args=(port, f"127.0.2.{i + 1}", head, body, gib, result, name))
                   for i, (name, (head, body)) in enumerate(cases.items())]
        for t in threads:
            t.start()
        check_legit(label, port, region, failures)
        for t in threads:
            t.join(timeout=60)
        hwm_after = memory_kb(server.pid, "VmHWM")
        for name in cases:
            sent, cut, _ = result.get(name, (None, False, None))
            print(f"  {name}: cut off after {sent / (1 << 20):.1f} MiB" if cut else f"  {name}: NOT cut off")
            if not cut:
                failures.append(f"{label}: the {name} was not cut off (sent {sent} bytes)")
            elif sent > 64 << 20:
                failures.append(f"{label}: the {name} was cut off only after {sent} bytes")
        growth_mib = (hwm_after - hwm_before) / 1024
        print(f"  server peak memory: {hwm_before / 1024:.1f} MiB before, {hwm_after / 1024:.1f} MiB after")
        if growth_mib > 32:
            failures.append(f"{label}: the server's peak memory grew by {growth_mib:.1f} MiB")
    finally:
        sigterm_and_wait(server, label, failures)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seqloc", required=True)
    parser.add_argument("--cache", required=True)
    parser.add_argument("--case", choices=["slowloris", "idle", "hostile"], action="append")
    args = parser.parse_args()
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    wanted = 4096
    if soft < wanted:
        resource.setrlimit(resource.RLIMIT_NOFILE, (wanted if hard == resource.RLIM_INFINITY else min(wanted, hard), hard))
    failures = []
    cases = {"slowloris": case_slowloris, "idle": case_idle, "hostile": case_hostile}
    for name in args.case or cases:
        cases[name](args, failures)
    for failure in failures:
        print("FAIL:", failure, file=sys.stderr)
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
