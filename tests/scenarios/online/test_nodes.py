"""The service's session checks the tag map's nodes when it connects: a node the server lacks, a
text or boolean node for a number and a trigger it cannot monitor each fail naming the role and the
node (they were read, written or subscribed cycle after cycle, the server saying only BadTypeMismatch or
BadNodeIdUnknown), an integer setpoint node or one holding a value in other units fails it too, and a prediction to
an integer node is rounded."""

import asyncio

from asyncua import ua

import scenarios.online as online
from scenarios.online.opcua import NodeError, Trigger
from scenarios.online.security import make_server

INSECURE = online.ClientSecurity(insecure=True)


async def _with_nodes(url, body):
    """A server with two Doubles, a String, a Boolean and an Int32 variable; ``body({name: node id})``."""
    server = await make_server(online.ServerSecurity(insecure=True))
    server.set_endpoint(url)
    idx = await server.register_namespace("urn:test")
    nodes = {}
    for name, value, vt in (("x", 1.5, ua.VariantType.Double), ("y", 0.5, ua.VariantType.Double), ("text", "a", ua.VariantType.String),
                            ("flag", False, ua.VariantType.Boolean), ("count", 0, ua.VariantType.Int32)):
        var = await server.nodes.objects.add_variable(idx, name, value, varianttype=vt)
        await var.set_writable()
        nodes[name] = var.nodeid.to_string()
    nodes["missing"] = f"ns={idx};s=no.such.node"
    await server.start()
    try:
        return await body(nodes)
    finally:
        await server.stop()


async def _open(url, read, write, trigger=None) -> str:
    """'' if a session opens on these roles, else NodeError's message."""
    conn = online.PlantConnection(url, INSECURE, read, write, timeout_s=2.0, trigger=trigger)
    try:
        await conn.open()
    except NodeError as exc:
        return str(exc)
    await conn.close()
    return ""


def test_nodes_that_cannot_take_the_services_values_fail_the_connection_naming_role_and_node(url):
    async def body(n):
        on_new = Trigger("p80_um", lambda fresh: None, 100.0)
        return {
            "double": await _open(url, {"p80_um": n["x"]}, {"setpoints.feed_tph": n["y"]}, on_new),
            "text": await _open(url, {}, {"setpoints.feed_tph": n["text"]}),
            "flag": await _open(url, {}, {"soft_sensor.p80_um": n["flag"]}),
            "status text": await _open(url, {}, {"status": n["text"]}),  # the status is text
            "missing": await _open(url, {}, {"setpoints.speed_frac_critical": n["missing"]}),
            "trigger": await _open(url, {"p80_um": n["missing"]}, {}, on_new),
        }

    got = asyncio.run(_with_nodes(url, body))
    assert got["double"] == "" and got["status text"] == ""
    assert got["text"].startswith("setpoints.feed_tph: node ") and "has data type String" in got["text"]
    assert got["flag"].startswith("soft_sensor.p80_um: node ") and "data type Boolean" in got["flag"]
    assert "no.such.node" in got["missing"] and "BadNodeIdUnknown" in got["missing"]
    assert got["missing"].startswith("setpoints.speed_frac_critical: node ")
    assert got["trigger"].startswith("cycle.on_new: the server refused to monitor p80_um's node")
    assert "BadNodeIdUnknown" in got["trigger"]


def test_an_integer_node_takes_a_prediction_rounded_and_no_setpoint(url):
    """A speed of 0.705 of critical written to an Int32 setpoint node landed as 1 (critical speed) while the audit
    recorded 0.705: an integer setpoint node fails the connection; a prediction is rounded there, not cut."""
    async def body(n):
        refused = await _open(url, {}, {"setpoints.speed_frac_critical": n["count"]})
        conn = online.PlantConnection(url, INSECURE, {"count": n["count"]}, {"soft_sensor.p80_um": n["count"]},
                                      distinct=False)  # read back where it is written
        await conn.open()
        try:
            await conn.write({"soft_sensor.p80_um": (211.6, ua.StatusCodes.Good)}, online.Clock().now())
            return refused, (await conn.read())["count"].value
        finally:
            await conn.close()

    refused, written = asyncio.run(_with_nodes(url, body))
    assert refused.startswith("setpoints.speed_frac_critical: node ") and "data type Int32" in refused
    assert "give a node of data type Double or Float" in refused
    assert written == 212  # int() wrote 211


def test_a_read_node_the_server_lacks_fails_the_connection_naming_role_and_node(url):
    """A mistyped measurement or mode node read BadNodeIdUnknown every cycle, logged once as an unusable reading:
    an optional power reading was never used and a missing mode node kept the service in manual, while a missing
    write node failed the connection. Every missing read node is named; nodes that exist open as before."""
    async def body(n):
        return (await _open(url, {"power_kw": n["missing"], "p80_um": n["x"], "mode": n["missing"] + ".mode"}, {}),
                await _open(url, {"p80_um": n["x"], "mode": n["text"]}, {"setpoints.feed_tph": n["y"]}))

    refused, opened = asyncio.run(_with_nodes(url, body))
    assert opened == ""
    assert refused.startswith("power_kw: node ") and "no.such.node" in refused and "BadNodeIdUnknown" in refused
    assert "; mode: node " in refused and "no.such.node.mode" in refused and "p80_um" not in refused


async def _serve_after_writing(scene, tags, parts, url, tmp_path, values) -> str:
    """'' if the service connects to the virtual plant after the plant's nodes were given ``values(feed setpoint
    held)`` (node id -> number), else NodeError's message."""
    from .conftest import LockStep

    ls = LockStep(scene, tags, parts, url, tmp_path / "audit")
    await ls.plant.start()
    try:
        server = ls.plant.server
        setpoint = server.read_attribute_value(ua.NodeId.from_string(tags.setpoints.feed_tph.node)).Value.Value
        for node, value in values(setpoint).items():
            await server.write_attribute_value(ua.NodeId.from_string(node),
                                               ua.DataValue(ua.Variant(value, ua.VariantType.Double)))
        try:
            await ls.service.connect()
        except NodeError as exc:
            return str(exc)
        await ls.service.shutdown("test end")
        return ""
    finally:
        await ls.plant.stop_server()


def test_a_setpoint_node_holding_a_value_in_other_units_fails_the_connection(small_scene, small_tags, small_parts,
                                                                             url, tmp_path):
    """A speed setpoint node in percent of critical (holding 72) took the service's 0.72 as 0.72 %, and a feed node
    in kg/h its 30 t/h as 30 kg/h: nothing compared the node with what the service writes there. The service's
    connection now refuses a node holding a number outside the setpoint's range in the service's units; a stopped
    mill's 0 and the plant's own setpoints connect."""
    async def connect_with(values: dict) -> str:
        nodes = {getattr(small_tags.setpoints, name).node: value for name, value in values.items()}
        return await _serve_after_writing(small_scene, small_tags, small_parts, url, tmp_path, lambda setpoint: nodes)

    assert asyncio.run(connect_with({})) == ""  # the virtual plant's own setpoints
    assert asyncio.run(connect_with({"speed_frac_critical": 0.0, "feed_tph": 0.0})) == ""  # a stopped mill
    refused = asyncio.run(connect_with({"speed_frac_critical": 72.0, "feed_tph": 30000.0}))
    speed, feed = (f"setpoints.{n}: node {getattr(small_tags.setpoints, n).node!r} holds " for n in
                   ("speed_frac_critical", "feed_tph"))
    assert speed + "72, outside [0, 1) of critical that the service writes there" in refused, refused
    assert feed + "30000, outside [0, " in refused and "(percent? kg/h?)" in refused


def test_one_node_written_two_ways_in_two_roles_fails_the_service_connection(url):
    """The tag map refuses one node id in two roles by its string; ``nsu=urn:test;i=1`` and ``ns=2;i=1`` (or
    ``ns=02``) are one node on the server and passed, so the P80 read and a feed setpoint could share a node. The
    service's connection compares the resolved ids; the same roles on nodes of their own open."""
    async def body(n):
        ns, ident = n["x"].split(";", 1)
        by_uri, padded = f"nsu=urn:test;{ident}", ns.replace("ns=", "ns=0") + ";" + ident
        return (await _open(url, {"p80_um": n["x"]}, {"setpoints.feed_tph": by_uri}),
                await _open(url, {"p80_um": padded, "power_kw": n["count"]}, {"heartbeat": n["x"]}),
                await _open(url, {"p80_um": n["x"]}, {"heartbeat": n["count"]}))

    by_uri, padded, own = asyncio.run(_with_nodes(url, body))
    assert by_uri.startswith("setpoints.feed_tph: node 'nsu=urn:test;") and "of p80_um" in by_uri, by_uri
    assert "each role needs a node of its own" in by_uri
    assert padded.startswith("heartbeat: node ") and "of p80_um" in padded and "power_kw" not in padded, padded
    assert own == ""


def test_a_feed_reading_in_other_units_than_its_setpoint_fails_the_connection(small_scene, small_tags, small_parts,
                                                                              url, tmp_path):
    """A feed measurement in kg/s (8.3 for 30 t/h) lay within its physical range and was Good: the service's first
    move in auto, from the actual feed, wrote 8.3 t/h. On connecting, a running feeder's reading and its setpoint
    node's value beyond a feeder's following are refused, naming both nodes; the plant's own values, a stopped
    feeder's 0 and a reading near its setpoint connect."""
    async def connect_with(reading_over_setpoint: float | None) -> str:
        node = small_tags.measurements.feed_tph.node
        return await _serve_after_writing(small_scene, small_tags, small_parts, url, tmp_path, lambda setpoint: (
            {} if reading_over_setpoint is None else {node: reading_over_setpoint * setpoint}))

    assert asyncio.run(connect_with(None)) == "" and asyncio.run(connect_with(0.0)) == ""
    assert asyncio.run(connect_with(0.9)) == ""
    refused = asyncio.run(connect_with(1.0 / 3.6))
    assert refused.startswith(f"measurements.feed_tph: node {small_tags.measurements.feed_tph.node!r} reads "), refused
    assert f"feed setpoint node {small_tags.setpoints.feed_tph.node!r} holds " in refused
    assert "0.278 times it" in refused and "(kg/s? kg/h?)" in refused


#: A node the plant has not given a value (a DCS starting up, a node never written).
NO_VALUE = ua.DataValue(ua.Variant(None, ua.VariantType.Null), ua.StatusCode(ua.StatusCodes.BadWaitingForInitialData))


def test_without_a_good_feed_setpoint_the_feed_reading_is_judged_against_the_feeds_the_service_writes(
        small_scene, small_tags, small_parts, url, tmp_path):
    """With no Good value in the feed setpoint node the check of the feed reading's units on connecting was skipped:
    a feed in kg/s (2.77 for 9.96 t/h) connected, and the first move in auto started from it. The reading is judged
    against the feeds the service may write (the setpoint's bounds and the scene's feed) within a feeder's following;
    the plant's own feed and a stopped feeder's 0 connect."""
    from .conftest import LockStep

    feed = small_tags.measurements.feed_tph.node
    ls = LockStep(small_scene, small_tags, small_parts, url, tmp_path / "audit")

    async def run():
        await ls.plant.start()  # one plant for every case: a start builds its integrators
        server = ls.plant.server
        actual = server.read_attribute_value(ua.NodeId.from_string(feed)).Value.Value
        await server.write_attribute_value(ua.NodeId.from_string(small_tags.setpoints.feed_tph.node), NO_VALUE)
        out = []
        for factor in (1.0, 0.0, 1.0 / 3.6, 1000.0):  # the plant's, stopped, kg/s, kg/h
            await server.write_attribute_value(ua.NodeId.from_string(feed),
                                               ua.DataValue(ua.Variant(factor * actual, ua.VariantType.Double)))
            try:
                await ls.service.connect()
                out.append("")
                conn, ls.service.conn = ls.service.conn, None
                await conn.close()
            except NodeError as exc:
                out.append(str(exc))
        await ls.plant.stop_server()
        return out

    own, stopped, *slips = asyncio.run(run())
    assert own == "" and stopped == ""
    for refused in slips:
        assert refused.startswith(f"measurements.feed_tph: node {feed!r} reads "), refused
        assert f"feed setpoint node {small_tags.setpoints.feed_tph.node!r} holds no Good value" in refused
        assert "[8, 30] t/h and the scene's 16 t/h" in refused and "(kg/s? kg/h?)" in refused
