"""Renders the 3-D scene of a recording (a station's `<site>.mcap` or a `session.mcap`) as a PNG,
top-down (x-y) and from the side (x-z), at one time: what Foxglove's 3-D panel shows, drawn from
the file alone. The `/scene` entities and `/tf` frames are decoded with the protobuf
FileDescriptorSet each schema carries (the `mcap` and `protobuf` packages), as a viewer does;
every entity is placed by its frame's newest transform at that time; `matplotlib` draws.

usage: render_scene.py FILE.mcap OUT.png [--at SECONDS]
  --at: seconds from the first message (default: when the copies are furthest apart, from
  `/divergence` in a session file; else the middle of the recording).
"""
import argparse
import bisect
import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
import json  # noqa: E402


def decoder(schema):
    fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    pool = descriptor_pool.DescriptorPool()
    for f in fds.file:
        pool.Add(f)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))


def qmul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


def rotate(q, v):
    x, y, z, w = q
    u = (x, y, z)
    cross = lambda a, b: (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
    t = cross(u, v)
    t2 = cross(u, t)
    return tuple(v[i] + 2 * w * t[i] + 2 * t2[i] for i in range(3))


def compose(frame, pose):
    """A primitive's pose (position, quaternion) in `world`, from its frame's and its own."""
    (ft, fq), (p, q) = frame, pose
    r = rotate(fq, p)
    return (tuple(ft[i] + r[i] for i in range(3)), qmul(fq, q))


def hull(points):
    pts = sorted(set(points))
    if len(pts) < 3:
        return pts
    cross = lambda o, a, b: (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


def surface(kind, size):
    """Points on a primitive's surface in its own axes (enough for its outline from any side)."""
    sx, sy, sz = size.x / 2, size.y / 2, size.z / 2
    if kind == "cubes":
        return [(a * sx, b * sy, c * sz) for a in (-1, 1) for b in (-1, 1) for c in (-1, 1)]
    n = 48
    ring = [(math.cos(2 * math.pi * k / n), math.sin(2 * math.pi * k / n)) for k in range(n)]
    if kind == "cylinders":
        return [(c * sx, s * sy, h * sz) for c, s in ring for h in (-1, 1)]
    # spheres: three great circles
    return ([(c * sx, s * sy, 0) for c, s in ring] + [(c * sx, 0, s * sz) for c, s in ring]
            + [(0, c * sy, s * sz) for c, s in ring])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("file")
    ap.add_argument("out")
    ap.add_argument("--at", type=float)
    a = ap.parse_args()
    tf, scenes, divergence, first = {}, [], [], None
    with open(a.file, "rb") as f:
        reader = make_reader(f)
        classes = {}
        for schema, channel, m in reader.iter_messages(topics=["/tf", "/scene", "/divergence"]):
            first = m.log_time if first is None else min(first, m.log_time)
            if channel.topic == "/divergence":
                divergence.append((m.log_time, json.loads(m.data)["max_m"]))
                continue
            cls = classes.setdefault(channel.topic, decoder(schema))
            msg = cls.FromString(m.data)
            if channel.topic == "/tf":
                t, r = msg.translation, msg.rotation
                tf.setdefault(msg.child_frame_id, []).append(
                    (m.log_time, ((t.x, t.y, t.z), (r.x, r.y, r.z, r.w))))
            else:
                scenes.append((m.log_time, msg))
    if not scenes:
        raise SystemExit(f"{a.file}: no /scene messages")
    if a.at is not None:
        at = first + int(a.at * 1e9)
    elif divergence:
        at = max(divergence, key=lambda d: d[1])[0]
    else:
        at = (scenes[0][0] + scenes[-1][0]) // 2
    # The entities as a viewer holds them at `at`: each update replaces entities by id.
    entities = {}
    for t, u in scenes:
        if t > at:
            break
        for e in u.entities:
            entities[e.id] = e
    times = {k: [t for t, _ in v] for k, v in tf.items()}

    def frame_pose(frame):
        if frame == "world":
            return ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
        i = bisect.bisect_right(times.get(frame, []), at) - 1
        return tf[frame][i][1] if i >= 0 else None

    views = [("top (x-y)", 0, 1, "y (m)"), ("side (x-z)", 0, 2, "z (m)")]
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.6), dpi=100)
    bounds = [math.inf, -math.inf, math.inf, -math.inf, math.inf, -math.inf]
    legend = {}
    for (title, i, j, ylabel), ax in zip(views, axes):
        for e in sorted(entities.values(), key=lambda e: (e.id != "environment", e.id)):
            fp = frame_pose(e.frame_id)
            if fp is None:
                continue
            env = e.id == "environment"
            for kind in ("cubes", "cylinders", "spheres"):
                for p in getattr(e, kind):
                    pose = compose(fp, ((p.pose.position.x, p.pose.position.y, p.pose.position.z),
                                        (p.pose.orientation.x, p.pose.orientation.y, p.pose.orientation.z,
                                         p.pose.orientation.w)))
                    pts = [tuple(pose[0][k] + v[k] for k in range(3)) for v in
                           (rotate(pose[1], s) for s in surface(kind, p.size))]
                    if not env:
                        for w in pts:
                            for k in range(3):
                                bounds[2 * k] = min(bounds[2 * k], w[k])
                                bounds[2 * k + 1] = max(bounds[2 * k + 1], w[k])
                    c = p.color
                    poly = hull([(w[i], w[j]) for w in pts])
                    ax.fill([q[0] for q in poly], [q[1] for q in poly], color=(c.r, c.g, c.b),
                            alpha=0.15 if env else max(0.35, c.a), lw=0.8,
                            ec=(c.r * 0.6, c.g * 0.6, c.b * 0.6), zorder=0 if env else 2)
                    if kind == "cylinders" or (kind == "cubes" and not env):
                        legend.setdefault(e.id, (c.r, c.g, c.b))
            for arrow in e.arrows:
                pose = compose(fp, ((arrow.pose.position.x, arrow.pose.position.y, arrow.pose.position.z),
                                    (arrow.pose.orientation.x, arrow.pose.orientation.y,
                                     arrow.pose.orientation.z, arrow.pose.orientation.w)))
                d = rotate(pose[1], (1.0, 0.0, 0.0))
                n = arrow.shaft_length + arrow.head_length
                c = arrow.color
                ax.annotate("", xy=(pose[0][i] + d[i] * n, pose[0][j] + d[j] * n), xytext=(pose[0][i], pose[0][j]),
                            arrowprops=dict(arrowstyle="-|>", color=(c.r, c.g, c.b), lw=1.5), zorder=3)
        ax.set_title(title)
        ax.set_xlabel("x (m)")
        ax.set_ylabel(ylabel)
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
    margin = 0.06
    for (title, i, j, _), ax in zip(views, axes):
        if bounds[2 * i] < math.inf:
            cx, cy = (bounds[2 * i] + bounds[2 * i + 1]) / 2, (bounds[2 * j] + bounds[2 * j + 1]) / 2
            half = max(bounds[2 * i + 1] - bounds[2 * i], bounds[2 * j + 1] - bounds[2 * j]) / 2 + margin
            ax.set_xlim(cx - half, cx + half)
            ax.set_ylim(cy - half, cy + half)
    handles = [plt.Line2D([], [], marker="s", ls="", color=c, markersize=10, label=k) for k, c in legend.items()]
    fig.legend(handles=handles, loc="lower center", ncol=max(1, len(handles)), frameon=False)
    fig.suptitle(f"{a.file.split('/')[-1]}: the 3-D scene at {(at - first) / 1e9:.2f} s "
                 f"({len(entities)} entities, {len(tf)} frames)")
    fig.tight_layout(rect=(0, 0.06, 1, 0.95))
    fig.savefig(a.out)
    print(f"{a.out}: {len(entities)} entities at {(at - first) / 1e9:.2f} s")


if __name__ == "__main__":
    main()
