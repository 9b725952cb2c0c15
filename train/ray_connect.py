"""Joining Ray as users run it: one place that decides which cluster ``nbs train --backend ray`` and
``nbs compare --backend ray`` use, and says so when it cannot.

- ``--address HOST:PORT`` (or ``ray://HOST:PORT``): the address is first checked to answer a TCP
  connect within :data:`PROBE_TIMEOUT` seconds, then joined. ``ray.init`` itself retries an address
  where nothing listens for minutes without a word; a refusal with the address is what a user needs.
- ``--address auto``: Ray's own search (``RAY_ADDRESS``, the cluster ``ray start`` recorded, else the one
  Ray instance running on this machine); ``--address local``: a new local instance, whatever runs.
- no ``--address``: ``RAY_ADDRESS`` when it is set, else the cluster ``ray start`` runs on this machine
  (Ray's record of it, which ``ray.init()`` reads too), else a new local instance with the command's CPU
  count. ``ray.init(num_cpus=N)`` refuses to join a running cluster (the cluster's CPUs are its own), so
  the CPU count is passed only to an instance started here.

A local instance another program started with ``ray.init`` (not ``ray start``) is not joined unasked: it
ends when that program does, and with it whatever ran on it. ``--address auto`` joins it on purpose.

This module imports neither torch nor stable-baselines3: :mod:`train.compare` uses it as
:mod:`train.ray_rollouts` does.
"""

from __future__ import annotations

import os
import socket
from dataclasses import dataclass

from nbs_env.config.checks import parse_int
from nbs_env.errors import ConfigError

__all__ = [
    "ADDRESS_HELP",
    "ADDRESS_VARIABLE",
    "PROBE_TIMEOUT",
    "RayConnection",
    "RayConnectionError",
    "connect_ray",
    "resolve_address",
]

#: Seconds a cluster's address has to answer a TCP connect. A head node on a LAN or in one cloud region
#: answers within milliseconds, one behind a slow VPN within a second or two; past 5 s a user is better
#: told that nothing answers than left waiting on ``ray.init``'s own retries.
PROBE_TIMEOUT = 5.0
#: Ray's variable naming the cluster to join (read by ``ray.init`` and Ray's own command line).
ADDRESS_VARIABLE = "RAY_ADDRESS"
#: Ray's variable for its token authentication (``token`` or ``disabled``).
AUTH_VARIABLE = "RAY_AUTH_MODE"
#: ``--address``'s help, one wording for ``nbs train`` and ``nbs compare``.
ADDRESS_HELP = (
    "the Ray cluster to join: HOST:PORT (checked to answer first), auto or local (default: RAY_ADDRESS, else the "
    "cluster ray start runs on this machine, else a local instance)"
)


class RayConnectionError(ConfigError):
    """No Ray cluster to join at the address given (nothing answers, or not ``HOST:PORT``), or Ray
    itself missing; the message names the address and where it came from."""


@dataclass(frozen=True)
class RayConnection:
    """Where a command's Ray work runs.

    Attributes
    ----------
    address : str or None
        The cluster joined (``host:port``, ``ray://host:port``); None: a local instance started here.
    source : str
        Where the address came from: ``"--address"``, ``"RAY_ADDRESS"``, ``"ray start"`` (the cluster
        ``ray start`` recorded on this machine), or ``"local"`` (none: an instance started here).
    """

    address: str | None
    source: str

    @property
    def local(self) -> bool:
        """Whether the work runs on an instance started here, with this machine's cores."""
        return self.address is None


def _named(address: str, source: str) -> str:
    """How a message names ``address``: as the user gave it (``--address A``, ``RAY_ADDRESS=A``)."""
    return f"{ADDRESS_VARIABLE}={address}" if source == ADDRESS_VARIABLE else f"{source} {address}"


def _probe(address: str, source: str, timeout: float) -> None:
    """Raise :class:`RayConnectionError` unless ``address`` (``[ray://]HOST:PORT``) answers a TCP connect;
    ``source`` is where the address came from, for the message."""
    scheme, sep, rest = address.partition("://")
    if sep and scheme != "ray":
        return  # another protocol (a hosted service's): only Ray can tell whether it answers
    hostport = rest if sep else address
    host, colon, port_text = hostport.rpartition(":")
    host = host.strip("[]")  # an IPv6 literal, [::1]:6379
    try:
        port = parse_int(port_text)
    except ValueError:
        port = 0
    if not colon or not host or not 1 <= port <= 65535:
        raise RayConnectionError(
            f"{_named(repr(address), source)}: expected HOST:PORT, e.g. 10.0.0.5:6379 (the head node's address, "
            "which ray start --head prints), ray://HOST:PORT, auto, or local"
        )
    try:
        with socket.create_connection((host, port), timeout=timeout):
            pass
    except OSError as exc:
        reason = f"no answer within {timeout:g} s" if isinstance(exc, TimeoutError) else exc.strerror or exc
        instead = f"unset {ADDRESS_VARIABLE}" if source == ADDRESS_VARIABLE else "leave out --address"
        raise RayConnectionError(
            f"{_named(address, source)}: nothing answers at {host}:{port} ({reason}); start the cluster there "
            f"(ray start --head), or {instead} to start a local instance"
        ) from None


def _recorded_cluster() -> str | None:
    """The address of the cluster ``ray start`` recorded on this machine (what ``ray.init()`` joins by
    itself), or None. Ray keeps the record in its temporary folder (``$RAY_TMPDIR/ray``, else
    ``/tmp/ray``); where its private layout moves, nothing is found and a local instance starts."""
    try:
        from ray._private.services import find_bootstrap_address
    except ImportError:
        return None
    try:
        return find_bootstrap_address(None) or None
    except OSError:
        return None


def resolve_address(address: str | None, timeout: float = PROBE_TIMEOUT) -> RayConnection:
    """Which cluster :func:`connect_ray` would join, checked to answer, without joining it.

    Parameters
    ----------
    address : str or None
        The command's ``--address``: ``HOST:PORT``, ``ray://HOST:PORT``, ``auto``, ``local``, or None.
    timeout : float
        Seconds an address has to answer a TCP connect.

    Returns
    -------
    RayConnection
        The address to join and where it came from; ``address`` None for a local instance.

    Raises
    ------
    RayConnectionError
        The address given (or ``RAY_ADDRESS``) is not ``HOST:PORT``, nothing answers there, or
        ``auto`` finds no running cluster.
    """
    source = "--address"
    if not address:
        address, source = os.environ.get(ADDRESS_VARIABLE, "").strip() or None, ADDRESS_VARIABLE
    if address is None:
        recorded = _recorded_cluster()
        if recorded is None:
            return RayConnection(None, "local")
        try:
            _probe(recorded, "ray start", timeout)
        except RayConnectionError:
            # A record that outlived its cluster (a machine restarted, a head killed): ray.init() would
            # wait on it; a local instance is what no --address asks for.
            return RayConnection(None, "local")
        return RayConnection(recorded, "ray start")
    if address == "local":
        return RayConnection(None, "local")
    if address == "auto":
        try:
            from ray._private.services import canonicalize_bootstrap_address_or_die

            found = canonicalize_bootstrap_address_or_die("auto")
        except ImportError:
            found = _recorded_cluster()
        except (ConnectionError, ValueError) as exc:
            raise RayConnectionError(f"{_named('auto', source)}: {exc}") from None
        if found is None:
            raise RayConnectionError(f"{_named('auto', source)}: no running Ray cluster on this machine")
        _probe(found, source, timeout)
        return RayConnection(found, source)
    _probe(address, source, timeout)
    return RayConnection(address, source)


def connect_ray(address: str | None, num_cpus: int, timeout: float = PROBE_TIMEOUT) -> RayConnection:
    """Join the cluster :func:`resolve_address` names, or start a local instance with ``num_cpus`` CPUs.

    Parameters
    ----------
    address : str or None
        The command's ``--address`` (see :func:`resolve_address`).
    num_cpus : int
        CPUs of a local instance started here (a cluster joined brings its own).
    timeout : float
        Seconds an address has to answer a TCP connect.

    Returns
    -------
    RayConnection
        Where the work runs. The caller ends it with ``ray.shutdown()``: that stops a local instance
        and only leaves a cluster joined.

    Raises
    ------
    RayConnectionError
        Ray is not installed, no cluster answers at the address, or Ray refuses to join it.
    """
    try:
        import ray
    except ImportError:
        raise RayConnectionError('--backend ray needs Ray: pip install "nbs-env[cluster]"') from None
    connection = resolve_address(address, timeout)
    if connection.local:
        # "local": a new instance even where a record of another names one (checked stale above).
        ray.init(address="local", num_cpus=num_cpus, include_dashboard=False, log_to_driver=False)
        return connection
    # The cluster `ray start` recorded is joined as ray.init() joins it by itself (address None), which
    # also turns on Ray's token authentication where a token is kept; one the user named, at its address.
    target = None if connection.source == "ray start" else connection.address
    try:
        ray.init(address=target, log_to_driver=False)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        # Ray turns token authentication on for a named address only when asked: the likeliest refusal.
        auth = (
            f"; a cluster with token authentication (Ray's default) is joined with {AUTH_VARIABLE}=token"
            if AUTH_VARIABLE not in os.environ
            else ""
        )
        raise RayConnectionError(
            f"{_named(connection.address, connection.source)}: Ray could not join the cluster there ({first}){auth}"
        ) from None
    return connection
