"""No socket of ours listens on a non-loopback address: `up`, its router and every service it starts."""
import ipaddress
import os
import signal
from pathlib import Path

from omninav.services.runtime.zenoh_config import open_client

from conftest import wait_until
from launching import TALKER_LISTENER, count_echoes, descendants, echo_subscriber

TCP_LISTEN = "0A"


def _address(hex_address: str) -> tuple[ipaddress.IPv4Address | ipaddress.IPv6Address, int]:
    """/proc/net's 'HEX_IP:HEX_PORT': the IP is in the kernel's byte order, one 32-bit word at a time."""
    hex_ip, hex_port = hex_address.split(":")
    raw = bytes.fromhex(hex_ip)
    words = b"".join(raw[i:i + 4][::-1] for i in range(0, len(raw), 4))
    return ipaddress.ip_address(words), int(hex_port, 16)


def test_address_parsing():
    assert _address("0100007F:1D1F") == (ipaddress.ip_address("127.0.0.1"), 7455)
    assert _address("00000000000000000000000001000000:0050") == (ipaddress.ip_address("::1"), 80)
    assert _address("0000000000000000FFFF00000100007F:0050") == (ipaddress.ip_address("::ffff:127.0.0.1"), 80)


def socket_inodes(pid: int) -> set[str]:
    inodes = set()
    fd_dir = Path(f"/proc/{pid}/fd")
    for fd in fd_dir.iterdir():
        try:
            target = os.readlink(fd)
        except FileNotFoundError:  # closed while we looked
            continue
        if target.startswith("socket:["):
            inodes.add(target[8:-1])
    return inodes


def inet_sockets() -> list[tuple]:
    """(table, inode, state, local address, local port) of every TCP and UDP socket."""
    rows = []
    for table in ("tcp", "tcp6", "udp", "udp6"):
        lines = Path(f"/proc/net/{table}").read_text().splitlines()[1:]
        for line in lines:
            fields = line.split()
            ip, port = _address(fields[1])
            rows.append((table, fields[9], fields[3], ip, port))
    return rows


def is_loopback(ip) -> bool:
    return ip.is_loopback or (ip.version == 6 and ip.ipv4_mapped is not None and ip.ipv4_mapped.is_loopback)


def test_every_socket_of_up_and_its_services_is_on_loopback(up, endpoint):  # noqa: F811
    launcher = up(TALKER_LISTENER)
    echoes = []
    with open_client(endpoint) as session:  # data flowing: every process has opened its sockets
        sub = echo_subscriber(session, echoes)
        wait_until(lambda: count_echoes(echoes) >= 3, 30, what="echoes through the listener")
        sub.undeclare()

    pids = [launcher.pid, *descendants(launcher.pid)]
    assert len(pids) >= 3  # up, talker, listener
    ours = set().union(*(socket_inodes(pid) for pid in pids))
    listening, checked = [], []
    for table, inode, state, ip, port in inet_sockets():
        if inode not in ours or (table.startswith("udp") and port == 0):  # an unbound UDP socket
            continue
        checked.append((table, state, ip, port))  # connected TCP sockets too: their local end
        if table.startswith("tcp") and state == TCP_LISTEN:
            listening.append(port)
    assert listening, "found no listening socket (the router's), so this test would prove nothing"
    assert int(endpoint.rpartition(":")[2]) in listening
    offending = [s for s in checked if not is_loopback(s[2])]
    assert offending == [], f"sockets not on loopback: {offending}"
    assert up.procs.stop(launcher, signal.SIGINT) == 0
