#!/usr/bin/env python3
"""Soak monitor: subscribes to every map output as rviz and a planner would,
and writes one CSV row per second: the manager's resident memory, the bytes
each output carried, and the two nodelets' diagnostics (updates fused and
lost, fusion and mapper p50 / p99 over that second). Ends on SIGINT/SIGTERM.

usage: soak_monitor.py OUT.csv MANAGER_PID
"""
import csv
import os
import signal
import sys
import threading
import time

import rospy
from diagnostic_msgs.msg import DiagnosticArray

OUTPUTS = ['/octomap_binary', '/octomap_full', '/occupied_cells_vis_array', '/free_cells_vis_array',
           '/octomap_point_cloud_centers', '/projected_map']
DIAGNOSTICS = {  # CSV column: (status name ends with, key)
    'updates_received': ('accumulator', 'updates received'),
    'updates_lost': ('accumulator', 'updates lost'),
    'updates_refused': ('accumulator', 'updates refused'),
    'leaves': ('accumulator', 'leaves'),
    'fusion_p50_ms': ('accumulator', 'fusion time p50 since last report [ms]'),
    'fusion_p99_ms': ('accumulator', 'fusion time p99 since last report [ms]'),
    'images_processed': ('mapper', 'images processed'),
    'mapper_p50_ms': ('mapper', 'processing time p50 since last report [ms]'),
    'mapper_p99_ms': ('mapper', 'processing time p99 since last report [ms]'),
}


def rss_mib(pid):
    try:
        with open(f'/proc/{pid}/status') as f:
            for line in f:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float('nan')


def main():
    out, pid = sys.argv[1], int(sys.argv[2])
    rospy.init_node('soak_monitor', disable_signals=True)
    lock = threading.Lock()
    sent = {t: 0 for t in OUTPUTS}
    diag = {k: float('nan') for k in DIAGNOSTICS}

    def on_output(topic):
        def callback(msg):
            with lock:
                sent[topic] += len(msg._buff)
        return callback

    def on_diagnostics(msg):
        with lock:
            for status in msg.status:
                values = {kv.key: kv.value for kv in status.values}
                for column, (name, key) in DIAGNOSTICS.items():
                    if status.name.endswith(name) and key in values:
                        diag[column] = float(values[key])

    for topic in OUTPUTS:
        rospy.Subscriber(topic, rospy.AnyMsg, on_output(topic), queue_size=100, buff_size=1 << 26)
    rospy.Subscriber('/diagnostics', DiagnosticArray, on_diagnostics, queue_size=100)

    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    columns = ['t_s', 'rss_mib'] + [t.strip('/') + '_bytes' for t in OUTPUTS] + list(DIAGNOSTICS)
    start = time.monotonic()
    with open(out, 'w', newline='') as f:
        writer = csv.writer(f)
        writer.writerow(columns)
        while not stop.wait(1.0):
            with lock:
                row = [f'{time.monotonic() - start:.1f}', f'{rss_mib(pid):.1f}'] + [sent[t] for t in OUTPUTS]
                row += [diag[k] for k in DIAGNOSTICS]
                for t in OUTPUTS:
                    sent[t] = 0
            writer.writerow(row)
            f.flush()
            if not os.path.exists(f'/proc/{pid}'):
                break
    rospy.signal_shutdown('done')


if __name__ == '__main__':
    main()
