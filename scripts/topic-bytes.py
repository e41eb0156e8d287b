#!/usr/bin/python3
"""Bytes a topic's publishers have sent over TCP, from each publishing node's getBusStats.

Messages passed inside one process (nodelets in a manager, by shared pointer) are not serialised
and count nothing here; every subscriber in another process gets (and deserialises) its own copy.
Usage: topic-bytes.py TOPIC [--frames N]  →  JSON on stdout
"""
import json
import sys
import xmlrpc.client

import rosgraph


def main():
    if len(sys.argv) < 2 or sys.argv[1].startswith("-"):
        print(__doc__, file=sys.stderr)
        return 2
    topic = sys.argv[1]
    frames = int(sys.argv[sys.argv.index("--frames") + 1]) if "--frames" in sys.argv else 0
    master = rosgraph.Master("/topic_bytes")
    pubs, subs, _ = master.getSystemState()
    publishers = next((nodes for t, nodes in pubs if t == topic), [])
    subscribers = next((nodes for t, nodes in subs if t == topic), [])
    result = {"topic": topic, "publishers": {}, "subscribers": sorted(subscribers), "bytes_sent": 0, "messages_sent": 0}
    for node in publishers:
        code, msg, stats = xmlrpc.client.ServerProxy(master.lookupNode(node)).getBusStats("/topic_bytes")
        if code != 1:
            raise RuntimeError("getBusStats of %s failed: %s" % (node, msg))
        for pub_topic, _data_sent, connections in stats[0]:
            if pub_topic != topic:
                continue
            sent = sum(c[1] for c in connections)
            result["publishers"][node] = {"tcp_connections": len(connections), "bytes_sent": sent}
            result["bytes_sent"] += sent
            result["messages_sent"] = max([result["messages_sent"]] + [c[2] for c in connections])
    if frames > 0:
        result["frames"] = frames
        result["bytes_sent_per_frame"] = result["bytes_sent"] / frames
    print(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
