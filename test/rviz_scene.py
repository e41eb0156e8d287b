#!/usr/bin/env python3
"""Publishes, latched, what the cell's rviz view shows after a scan: a located part as
model_matching draws it (/detections/markers: a magenta TRIANGLE_LIST, here a 40 mm cube on the
table) and a scan (/scan/cloud: the table top with intensities, most at mid-range). For
test/rviz_headless.sh."""
import struct

import rospy
from geometry_msgs.msg import Point
from sensor_msgs.msg import PointCloud2, PointField
from visualization_msgs.msg import Marker, MarkerArray


def cube(size):
    h = size / 2
    corners = [(x, y, z) for x in (-h, h) for y in (-h, h) for z in (0, size)]
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    return [Point(*corners[i]) for f in faces for i in f]


def main():
    rospy.init_node("rviz_scene")
    markers = rospy.Publisher("detections/markers", MarkerArray, queue_size=1, latch=True)
    cloud = rospy.Publisher("scan/cloud", PointCloud2, queue_size=1, latch=True)
    m = Marker()
    m.header.frame_id = "base_link"
    m.ns = "detections"
    m.type = Marker.TRIANGLE_LIST
    m.pose.position.x, m.pose.position.y = 0.52, 0.0
    m.pose.orientation.w = 1.0
    m.scale.x = m.scale.y = m.scale.z = 1.0
    m.color.r, m.color.g, m.color.b, m.color.a = 0.9, 0.1, 0.8, 0.9
    m.points = cube(0.04)
    markers.publish(MarkerArray(markers=[m]))
    data = bytearray()
    n = 0
    for i in range(170):
        for j in range(120):
            value = 0.0 if n == 0 else (255.0 if n == 1 else 128.0)
            data += struct.pack("<ffff", 0.35 + 0.002 * i, -0.12 + 0.002 * j, 0.0, value)
            n += 1
    c = PointCloud2()
    c.header.frame_id = "base_link"
    c.header.stamp = rospy.Time.now()
    c.height, c.width = 1, n
    c.fields = [PointField(name, 4 * k, PointField.FLOAT32, 1) for k, name in enumerate(("x", "y", "z", "intensity"))]
    c.point_step, c.row_step, c.is_dense = 16, 16 * n, True
    c.data = bytes(data)
    cloud.publish(c)
    rospy.spin()


if __name__ == "__main__":
    main()
