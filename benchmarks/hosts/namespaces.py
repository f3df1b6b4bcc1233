"""Several "hosts" on one machine: network namespaces joined by a bridge in a namespace of its own.

    with NetnsHosts(3) as net:              # `python -m benchmarks lossy`, the multi-host tests
        net.addresses                       # ['10.213.7.1', '10.213.7.2', '10.213.7.3']
        net.run(0, ["ip", "addr"])          # a bounded command inside host 0
        procs.start(argv, env, 30, "a", prefix=net.prefix(1))   # a process inside host 1
        net.link_down(2); net.link_up(2)    # host 2's only link
        net.add_loss(1, percent=10)         # nftables: drop 10% of what host 1 receives

Layout (names unique to the run, ``pmnet<pid>x<random>``): K host namespaces ``<tag>h<i>``, each
with ``lo`` up and one veth ``eth0`` holding ``10.213.<net>.<i+1>/24``; the other end of each veth
(``h<i>``) sits in the bridge namespace ``<tag>br`` on bridge ``br0`` (a bridge cannot be moved
into a namespace, so it is created inside).  Nothing is created in the root namespace and the
namespaces have no route out: their traffic can reach only each other.
``Capture(directory, root_interfaces())`` runs tcpdump on the root namespace's non-loopback
interfaces (and ``Capture(directory, ["br0"], net.bridge)``, as a control, on the bridge) for
RTPS/DDS packets.  ``close`` deletes every namespace (with it every veth, the bridge and the
nftables tables); it runs even when the run fails or is interrupted.
"""

import contextlib
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time

PREFIX = "pmnet"
# DDS: the RTPS magic at the start of the UDP payload, or the well-known ports of domains 0..1.
DDS_FILTER = "udp and (udp[8:4] = 0x52545053 or portrange 7400-7700)"
LOSS_TABLE = "polymatch_loss"
_RECEIVE = """import socket, sys, time
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.bind(("0.0.0.0", int(sys.argv[1])))
print("bound", flush=True)
sock.settimeout(0.2)
expected, end = int(sys.argv[3]), time.monotonic() + float(sys.argv[2])
got, last = 0, None
while got < expected and time.monotonic() < end:
    if last is not None and time.monotonic() - last > 0.5:
        break                                   # the sender is done; the rest was lost
    try:
        sock.recv(64)
        got, last = got + 1, time.monotonic()
    except OSError:
        pass
print(got)
"""
_SEND = """import socket, sys, time
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
for _ in range(int(sys.argv[3])):
    try:
        sock.sendto(b"x", (sys.argv[1], int(sys.argv[2])))
    except OSError:
        pass
    time.sleep(0.002)
"""


def unavailable_reason(tools=()):
    """Why the namespace hosts cannot be used here (None when they can)."""
    if os.geteuid() != 0:
        return "network namespaces need root"
    for tool in ("ip",) + tuple(tools):
        if shutil.which(tool) is None:
            return f"{tool} is not installed (scripts/install-system-packages.sh installs it)"
    name = f"{PREFIX}{os.getpid()}probe"
    made = subprocess.run(["ip", "netns", "add", name], check=False, capture_output=True,
                          text=True, timeout=10)
    if made.returncode != 0:
        return f"ip netns add failed: {made.stderr.strip()}"
    subprocess.run(["ip", "netns", "del", name], check=False, capture_output=True, timeout=10)
    return None


def _ip(*argv, namespace=None, check=True):
    command = ["ip"] + (["-n", namespace] if namespace else []) + list(argv)
    done = subprocess.run(command, check=False, capture_output=True, text=True, timeout=15)
    if check and done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)}: {done.stderr.strip()}")
    return done


def namespaces():
    listed = subprocess.run(["ip", "netns", "list"], check=False, capture_output=True,
                            text=True, timeout=10)
    return [line.split()[0] for line in listed.stdout.splitlines() if line.strip()]


def remove_stale():
    """Delete namespaces left by an earlier run whose process no longer exists."""
    for name in namespaces():
        found = re.match(rf"{PREFIX}(\d+)x", name)
        if found and not os.path.exists(f"/proc/{found.group(1)}"):
            _ip("netns", "del", name, check=False)


class NetnsHosts:
    """K namespace hosts on one private bridge; a context manager that always cleans up."""

    def __init__(self, count, net=None):
        self.tag = f"{PREFIX}{os.getpid()}x{random.randrange(16 ** 4):04x}"
        self.net = random.randrange(1, 255) if net is None else net
        self.hosts = [f"{self.tag}h{i}" for i in range(count)]
        self.bridge = f"{self.tag}br"
        self.addresses = [f"10.213.{self.net}.{i + 1}" for i in range(count)]
        self.created = []
        self.udp_calls = 0

    def __enter__(self):
        try:
            self.create()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc):
        self.close()

    def _add_namespace(self, name):
        _ip("netns", "add", name)
        self.created.append(name)
        _ip("link", "set", "lo", "up", namespace=name)

    def create(self):
        remove_stale()
        self._add_namespace(self.bridge)
        _ip("link", "add", "br0", "type", "bridge", "mcast_snooping", "0", namespace=self.bridge)
        _ip("link", "set", "br0", "up", namespace=self.bridge)
        for index, (host, address) in enumerate(zip(self.hosts, self.addresses)):
            self._add_namespace(host)
            _ip("link", "add", "eth0", "type", "veth", "peer", "name", f"h{index}",
                "netns", self.bridge, namespace=host)
            _ip("link", "set", f"h{index}", "master", "br0", "up", namespace=self.bridge)
            _ip("addr", "add", f"{address}/24", "dev", "eth0", namespace=host)
            _ip("link", "set", "eth0", "up", namespace=host)
            # multicast (simple discovery) leaves through eth0 as well
            _ip("route", "add", "224.0.0.0/4", "dev", "eth0", namespace=host)

    def close(self):
        """Delete every namespace this object created (veths and the bridge go with them)."""
        for name in reversed(self.created):
            _ip("netns", "del", name, check=False)
        self.created = []

    def left_over(self):
        """The namespaces of this run that still exist (empty after ``close``)."""
        return [name for name in namespaces() if name.startswith(self.tag)]

    def prefix(self, index):
        """The command prefix that runs a program inside host ``index``."""
        return ("ip", "netns", "exec", self.hosts[index])

    def run(self, index, argv, seconds=30):
        """Run ``argv`` inside host ``index`` under ``timeout -k 5``; a CompletedProcess."""
        return subprocess.run(list(self.prefix(index)) + ["timeout", "-k", "5", str(seconds)]
                              + list(argv), check=False, capture_output=True, text=True,
                              timeout=seconds + 10, stdin=subprocess.DEVNULL)

    def udp_delivered(self, source, target, count=50, seconds=3.0):
        """Send ``count`` UDP datagrams from host ``source`` to host ``target``; how many arrived.

        Each call uses a port of its own, so datagrams held back by an earlier call (a link
        that was down) cannot be counted again.
        """
        self.udp_calls += 1
        port = 20000 + self.udp_calls
        receiver = subprocess.Popen(
            list(self.prefix(target)) + ["timeout", "-k", "2", str(seconds + 5), sys.executable,
                                         "-c", _RECEIVE, str(port), str(seconds),
                                         str(count)],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        try:
            deadline = time.monotonic() + 5
            while receiver.stdout.readline().strip() != "bound" and time.monotonic() < deadline:
                if receiver.poll() is not None:
                    break
            self.run(source, [sys.executable, "-c", _SEND, self.addresses[target], str(port),
                              str(count)], seconds=10)
            out, _ = receiver.communicate(timeout=seconds + 10)
        finally:
            if receiver.poll() is None:
                receiver.kill()
                receiver.wait(timeout=5)
        return int(out.split()[-1]) if out.split() and out.split()[-1].isdigit() else 0

    def link_down(self, index):
        _ip("link", "set", "eth0", "down", namespace=self.hosts[index])

    def link_up(self, index):
        _ip("link", "set", "eth0", "up", namespace=self.hosts[index])
        _ip("route", "replace", "224.0.0.0/4", "dev", "eth0", namespace=self.hosts[index])

    def add_loss(self, index, percent=10):
        """Drop ``percent``% of the packets host ``index`` receives on eth0 (nftables)."""
        if not 0 < percent <= 100:
            raise ValueError(f"loss {percent}% is not in (0, 100]")
        commands = [["nft", "add", "table", "inet", LOSS_TABLE],
                    ["nft", (f"add chain inet {LOSS_TABLE} in "
                             "{ type filter hook input priority 0; }")],
                    ["nft", "add", "rule", "inet", LOSS_TABLE, "in", "iifname", "eth0",
                     "numgen", "random", "mod", "100", "<", str(percent), "counter", "drop"]]
        for argv in commands:
            done = self.run(index, argv, seconds=10)
            if done.returncode != 0:
                raise RuntimeError(f"{' '.join(argv)}: {done.stderr.strip()}")

    def dropped(self, index):
        """Packets the loss rule of host ``index`` has dropped so far."""
        done = self.run(index, ["nft", "list", "table", "inet", LOSS_TABLE], seconds=10)
        found = re.search(r"counter packets (\d+)", done.stdout)
        return int(found.group(1)) if found else 0

    def remove_loss(self, index):
        self.run(index, ["nft", "delete", "table", "inet", LOSS_TABLE], seconds=10)


def _read(path):
    with open(path) as text:
        return text.read()


def root_interfaces():
    """The root namespace's interfaces that are up, loopback excluded."""
    shown = _ip("-o", "link", "show", "up").stdout
    names = [line.split(":")[1].strip().split("@")[0] for line in shown.splitlines()]
    return [name for name in names if name != "lo"]


class Capture:
    """tcpdump for DDS packets on some interfaces (in the root namespace or one of ours).

    ``--immediate-mode`` hands every packet to tcpdump as it arrives.  Without it packets wait
    in the kernel's ring until a block fills or a 1 s timeout passes, and a capture stopped
    sooner writes nothing: a short run logged "0 packets captured" of the packets the filter
    had received.  ``matched()`` reads the kernel's count, drops included.
    """

    def __init__(self, directory, interfaces, namespace=None, label="root"):
        self.directory, self.namespace = directory, namespace
        self.files, self.procs = [], []
        self.interfaces = list(interfaces)
        self.label = label

    def __enter__(self):
        prefix = ["ip", "netns", "exec", self.namespace] if self.namespace else []
        for name in self.interfaces:
            path = os.path.join(self.directory, f"capture_{self.label}_{name}.pcap")
            log = open(path + ".log", "w")
            proc = subprocess.Popen(prefix + ["timeout", "-k", "5", "300", "tcpdump", "-i", name,
                                              "-n", "--immediate-mode", "-B", "16384", "-U",
                                              "-Z", "root", "-w", path, DDS_FILTER],
                                    stdout=log, stderr=subprocess.STDOUT)
            log.close()
            self.files.append(path)
            self.procs.append(proc)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            if all("listening on" in _read(path + ".log") for path in self.files):
                return self
            if any(proc.poll() is not None for proc in self.procs):
                break
            time.sleep(0.05)
        self.__exit__()
        raise RuntimeError("tcpdump did not start: " + " | ".join(
            _read(path + ".log").strip() for path in self.files))

    def __exit__(self, *exc):
        for proc in self.procs:
            if proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(proc.pid, signal.SIGINT)
        for proc in self.procs:
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5)

    def matched(self):
        """Packets the kernel's filter matched on these interfaces (tcpdump's own count).

        It counts what the kernel dropped as well, so a zero here does not depend on tcpdump
        having kept up: the strongest form of "nothing of ours was seen here".
        """
        total = 0
        for path in self.files:
            log = _read(path + ".log")
            received = re.search(r"(\d+) packets? received by filter", log)
            if received is None:
                raise RuntimeError(f"tcpdump did not report its counts: {log.strip()}")
            total += int(received.group(1))
        return total

    def addresses(self):
        """The IPv4 addresses the captured packets came from or went to."""
        found = set()
        for line in self.packets():
            found.update(re.findall(r"(\d+\.\d+\.\d+\.\d+)\.\d+", line))
        return found

    def packets(self):
        """The captured packets, one summary line each."""
        lines = []
        for path in self.files:
            if os.path.exists(path) and os.path.getsize(path) > 0:
                read = subprocess.run(["tcpdump", "-n", "-r", path], check=False,
                                      capture_output=True, text=True, timeout=30)
                lines += read.stdout.splitlines()
        return lines
