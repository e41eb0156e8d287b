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
        answer = xmlrpc.client.ServerProxy(master.lookupNode(node)).getBusStats("/topic_bytes")
        # roscpp answers [publish, subscribe]; rospy [code, message, [publish, subscribe, services]]
        if len(answer) == 3 and isinstance(answer[0], int):
            if answer[0] != 1:
                raise RuntimeError("getBusStats of %s failed: %s" % (node, answer[1]))
            answer = answer[2]
        for pub_topic, connections in ((t[0], t[-1]) for t in answer[0]):
            if pub_topic != topic:
                continue
            # a connection: [id, bytes sent, ..., messages sent, ...]; one that never sent a byte
            # is a subscriber in the same process (the message passed by pointer) or an idle one
            # roscpp reports the byte count as a 32-bit int: undo one wrap (2-4 GiB per connection)
            sent = [c[1] + 2**32 if c[1] < 0 else c[1] for c in connections]
            result["publishers"][node] = {"connections": len(connections),
                                          "connections_that_sent_bytes": sum(1 for b in sent if b > 0),
                                          "bytes_sent": sum(sent)}
            result["bytes_sent"] += sum(sent)
            result["messages_sent"] = max([result["messages_sent"]] + [c[-2] for c in connections])
    if frames > 0:
        result["frames"] = frames
        result["bytes_sent_per_frame"] = result["bytes_sent"] / frames
    print(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
