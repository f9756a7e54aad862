"""The service's OPC UA client: one session to the plant, every read of a cycle in one Read
request (values with status codes and source timestamps) and every write in one Write request,
typed as the server's nodes are typed; optionally a subscription that reports each new value
(a new source timestamp too) of one node, which starts the service's cycle."""

from __future__ import annotations

import asyncio
import math
from dataclasses import dataclass
from collections.abc import Callable
from datetime import datetime, timezone

from asyncua import Client, ua

from scenarios.online.quality import PlausibleRange, Reading, raw_number
from scenarios.online.security import ClientSecurity, secure_client

#: What a lost or refused connection raises (asyncua's status errors are UaError).
CONNECTION_ERRORS = (ConnectionError, OSError, asyncio.TimeoutError, ua.UaError)


class NodeError(ua.UaError):
    """A node of the tag map the plant server does not have, or cannot take the service's values:
    a connection attempt fails naming the role and node (and is retried: a server may load its
    address space late)."""


#: write roles whose values are numbers
NUMERIC_ROLES = ("setpoints.", "soft_sensor.")

#: asyncua's connection supervisor probes the server every interval with that time-out and drops
#: the session on a miss; the service's own requests find a loss at the next cycle, so the probe
#: waits this many request time-outs rather than taking a busy server for a dead one.
PROBE_TIMEOUTS = 4

#: Variant types of the node data types the service writes.
_VARIANTS = {ua.ObjectIds.Double: ua.VariantType.Double, ua.ObjectIds.Float: ua.VariantType.Float,
             ua.ObjectIds.Int16: ua.VariantType.Int16, ua.ObjectIds.Int32: ua.VariantType.Int32,
             ua.ObjectIds.Int64: ua.VariantType.Int64, ua.ObjectIds.UInt16: ua.VariantType.UInt16,
             ua.ObjectIds.UInt32: ua.VariantType.UInt32, ua.ObjectIds.UInt64: ua.VariantType.UInt64,
             ua.ObjectIds.String: ua.VariantType.String, ua.ObjectIds.Boolean: ua.VariantType.Boolean}
_INTEGERS = {ua.VariantType.Int16, ua.VariantType.Int32, ua.VariantType.Int64, ua.VariantType.UInt16,
             ua.VariantType.UInt32, ua.VariantType.UInt64}


def status_name(code: int) -> str:
    try:
        return ua.StatusCode(code).name
    except (KeyError, ValueError, AttributeError):
        return f"0x{code:08X}"


async def resolve(client: Client, node_id: str) -> ua.NodeId:
    """A node id string, with ``nsu=URI`` turned into the server's namespace index."""
    if node_id.startswith("nsu="):
        uri, rest = node_id[4:].split(";", 1)
        return ua.NodeId.from_string(f"ns={await client.get_namespace_index(uri)};{rest}")
    return ua.NodeId.from_string(node_id)


class _OnNew:
    """asyncua's subscription handler: each data change notification calls ``on_new(fresh)``;
    ``fresh`` is False for the first, the node's current value that a new monitored item reports
    at once (OPC UA Part 4, monitored items), not a new sample."""

    def __init__(self, on_new: Callable[[bool], None]):
        self.on_new = on_new
        self.reported = False

    def datachange_notification(self, node, val, data) -> None:
        fresh, self.reported = self.reported, True
        self.on_new(fresh)

    def status_change_notification(self, status) -> None:
        """The subscription's status changed (lost or timed out): the service finds a lost
        session at its next request and reconnects, which subscribes again."""


@dataclass
class Trigger:
    """Call ``on_new(fresh)`` at every new value of the read role ``role`` (a subscription: the
    server sends the value when it is written, within ``publishing_ms``; ``fresh`` is False for
    the value the node held when the subscription was made)."""

    role: str
    on_new: Callable[[bool], None]
    publishing_ms: float


class PlantConnection:
    """A session to the plant server for fixed read and write roles (role -> node id), and an
    optional :class:`Trigger`."""

    def __init__(self, url: str, security: ClientSecurity, read_roles: dict[str, str],
                 write_roles: dict[str, str], timeout_s: float = 2.0, trigger: Trigger | None = None,
                 write_ranges: dict[str, PlausibleRange] | None = None, distinct: bool = True):
        self.url, self.security, self.timeout_s = url, security, timeout_s
        #: every role needs a node of its own (the tag map's rule), checked again on the resolved node ids (False:
        #: a node read back where it is written, as tests do)
        self.distinct = distinct
        self.read_roles, self.write_roles = dict(read_roles), dict(write_roles)
        self.trigger = trigger
        #: write role -> the values the service writes there, in its units: a node holding another is refused
        self.write_ranges = dict(write_ranges or {})
        #: write role -> the number its node held when the session opened (Good and finite only)
        self.held_values: dict[str, float] = {}
        self.client: Client | None = None

    async def open(self) -> None:
        """Connect, authenticate and look up the nodes; raises a CONNECTION_ERRORS error."""
        client = Client(self.url, timeout=self.timeout_s, watchdog_intervall=PROBE_TIMEOUTS * self.timeout_s)
        client.name = client.description = "grindtwin serve"
        await secure_client(client, self.security)
        await client.connect()  # every step of it under the request time-out
        try:
            self._read_ids = [await resolve(client, n) for n in self.read_roles.values()]
            self._write_ids = {r: await resolve(client, n) for r, n in self.write_roles.items()}
            if self.distinct:
                self._check_distinct()
            types = await client.uaclient.read_attributes(list(self._write_ids.values()), ua.AttributeIds.DataType)
            self._variants = {role: self._variant(role, dv) for role, dv in zip(self._write_ids, types)}
            await self._check_held_values(client)
            if self.trigger is not None:
                await self._subscribe(client, self.trigger)
            await self._check_read_nodes(client)  # after the trigger's own, more specific, check
        except BaseException:
            await self._disconnect(client)
            raise
        self.client = client

    def _check_distinct(self) -> None:
        """NodeError naming two roles whose node ids, written differently, are one node once resolved (``nsu=URI;s=X``
        and ``ns=2;s=X``; ``ns=02;...``): the tag map's check compares the strings, and a feed setpoint and a speed
        setpoint written to one node, or a power read as the P80, would go unsaid."""
        roles = [*zip(self.read_roles.items(), self._read_ids),
                 *zip(self.write_roles.items(), self._write_ids.values())]
        seen: dict[ua.NodeId, tuple[str, str]] = {}
        same = []
        for (role, node), nid in roles:
            if nid in seen:
                same.append(f"{role}: node {node!r} is the node {seen[nid][1]!r} of {seen[nid][0]} "
                            f"({nid.to_string()} on this server); each role needs a node of its own")
            seen.setdefault(nid, (role, node))
        if same:
            raise NodeError("; ".join(same))

    async def _check_read_nodes(self, client: Client) -> None:
        """NodeError naming every read role whose node the server does not have (a node id mistyped in the tag
        map): its reads came back BadNodeIdUnknown cycle after cycle, logged once as an unusable reading, so
        an optional measurement was never used and a missing mode node kept the service in manual."""
        if not self._read_ids:
            return
        found = await client.uaclient.read_attributes(self._read_ids, ua.AttributeIds.DataType)
        missing = [f"{role}: node {node!r}: the server has no such variable ({status_name(dv.StatusCode.value)})"
                   for (role, node), dv in zip(self.read_roles.items(), found)
                   if dv.StatusCode is not None and not dv.StatusCode.is_good()]
        if missing:
            raise NodeError("; ".join(missing))

    async def _check_held_values(self, client: Client) -> None:
        """NodeError naming every write role (of ``write_ranges``) whose node holds a number outside the range of
        what the service writes there: a node in other units (a speed in percent of critical, a feed in kg/h) took
        the service's 0.72 of critical as 0.72 % and its 30 t/h as 30 kg/h, and the plant followed. A node without
        a usable number (Bad, empty) is not judged."""
        roles = [r for r in self.write_ranges if r in self._write_ids]
        if not roles:
            return
        held = await client.uaclient.read_attributes([self._write_ids[r] for r in roles], ua.AttributeIds.Value)
        wrong = []
        for role, dv in zip(roles, held):
            good = dv.StatusCode is None or dv.StatusCode.is_good()
            value = raw_number(dv.Value.Value if dv.Value is not None else None)
            if good and math.isfinite(value):
                self.held_values[role] = value
            if good and math.isfinite(value) and value not in self.write_ranges[role]:
                wrong.append(f"{role}: node {self.write_roles[role]!r} holds {value:g}, outside "
                             f"{self.write_ranges[role]} that the service writes there: a node in other units "
                             "(percent? kg/h?) would take its values in its own; give the node of the quantity in the "
                             "tag map's units")
        if wrong:
            raise NodeError("; ".join(wrong))

    def _variant(self, role: str, dv: ua.DataValue) -> ua.VariantType:
        """The variant type to write ``role``'s node with, from its DataType attribute; NodeError if
        the server has no such node, or if a number (a setpoint, a prediction) would go to a text or
        boolean node (each write was refused, BadTypeMismatch, cycle after cycle)."""
        node = self.write_roles[role]
        code = dv.StatusCode.value if dv.StatusCode is not None else 0
        if not ua.StatusCode(code).is_good():
            raise NodeError(f"{role}: node {node!r}: the server has no such variable ({status_name(code)})")
        dtype = dv.Value.Value if dv.Value is not None else None
        vt = _VARIANTS.get(dtype.Identifier if isinstance(dtype, ua.NodeId) else None, ua.VariantType.Double)
        if role.startswith(NUMERIC_ROLES) and vt in (ua.VariantType.String, ua.VariantType.Boolean):
            raise NodeError(f"{role}: node {node!r} has data type {vt.name}; a number is written there: give a "
                            "node of a numeric data type (Double, Float or an integer)")
        if role.startswith("setpoints.") and vt in _INTEGERS:  # 0.705 of critical was written as 1, audited 0.705
            raise NodeError(f"{role}: node {node!r} has data type {vt.name}; a setpoint written there is rounded to "
                            "a whole number after its limits and rate limits (a speed of 0.705 of critical lands "
                            "as 1), and the audit would record another value than the plant's: give a node of data "
                            "type Double or Float")
        return vt

    async def _subscribe(self, client: Client, trigger: Trigger) -> None:
        """Monitor the trigger's node; a notification at each change of its status, value or
        source timestamp (a frozen analyser's new report too)."""
        sub = await client.create_subscription(trigger.publishing_ms, _OnNew(trigger.on_new))
        item = ua.MonitoredItemCreateRequest()
        item.ItemToMonitor = ua.ReadValueId()
        item.ItemToMonitor.NodeId = self._read_ids[list(self.read_roles).index(trigger.role)]
        item.ItemToMonitor.AttributeId = ua.AttributeIds.Value
        item.MonitoringMode = ua.MonitoringMode.Reporting
        p = item.RequestedParameters = ua.MonitoringParameters()
        p.ClientHandle, p.SamplingInterval, p.QueueSize, p.DiscardOldest = 1, 0.0, 1, True
        p.Filter = ua.DataChangeFilter(Trigger=ua.DataChangeTrigger.StatusValueTimestamp)
        result = (await sub.create_monitored_items([item]))[0]
        if isinstance(result, ua.StatusCode) and not result.is_good():  # it said only BadNodeIdUnknown
            raise NodeError(f"cycle.on_new: the server refused to monitor {trigger.role}'s node "
                            f"{self.read_roles[trigger.role]!r} ({status_name(result.value)})")

    async def read(self) -> dict[str, Reading]:
        """Every read role's value, status and timestamps, in one request."""
        params = ua.ReadParameters()
        params.TimestampsToReturn = ua.TimestampsToReturn.Both
        for nid in self._read_ids:
            rv = ua.ReadValueId()
            rv.NodeId, rv.AttributeId = nid, ua.AttributeIds.Value
            params.NodesToRead.append(rv)
        values = await asyncio.wait_for(self._client().uaclient.read(params), timeout=self.timeout_s)
        out = {}
        for role, dv in zip(self.read_roles, values):
            code = dv.StatusCode.value if dv.StatusCode is not None else 0
            out[role] = Reading(dv.Value.Value if dv.Value is not None else None, code,
                                _aware(dv.SourceTimestamp), _aware(dv.ServerTimestamp), status_name(code))
        return out

    async def write(self, values: dict[str, tuple], source_time: datetime) -> dict[str, int]:
        """Write ``{role: (value, status code)}`` in one request; returns each role's result code."""
        roles = list(values)
        dvs = []
        for role in roles:
            value, code = values[role]
            vt = self._variants[role]
            if vt in _INTEGERS:  # a prediction only (_variant refuses integer setpoint nodes)
                value = int(round(value))  # int() alone cut 23.9 to 23
            variant = ua.Variant(None, ua.VariantType.Null) if value is None else ua.Variant(value, vt)
            dvs.append(ua.DataValue(variant, ua.StatusCode(code), source_time))
        res = await asyncio.wait_for(
            self._client().uaclient.write_attributes([self._write_ids[r] for r in roles], dvs, ua.AttributeIds.Value),
            timeout=self.timeout_s)
        return {r: s.value for r, s in zip(roles, res)}

    async def close(self) -> None:
        client, self.client = self.client, None
        if client is not None:
            await self._disconnect(client)

    async def _disconnect(self, client: Client) -> None:
        try:
            await asyncio.wait_for(client.disconnect(), timeout=self.timeout_s)
        except CONNECTION_ERRORS:
            pass  # the connection is gone either way

    def _client(self) -> Client:
        if self.client is None:
            raise ConnectionError("not connected")
        return self.client


def _aware(t: datetime | None) -> datetime | None:
    if t is None or t.tzinfo is not None:
        return t
    return t.replace(tzinfo=timezone.utc)
