"""Edits of an OSM extract for the update test and benchmark: the extract as OPL (`osmium cat -f
opl`), some road nodes moved, buildings deleted and added, written back as OPL in the order OSM
files keep (nodes, ways, relations, each by id) for `osmium derive-changes` to turn into a change
file. Seeded: the same edits for the same seed."""

import re


def read_opl(path):
    objects = []
    with open(path) as f:
        for line in f:
            line = line.rstrip("\n")
            if line:
                objects.append(line.split(" "))
    return objects


def field(obj, key):
    return next((f[1:] for f in obj[1:] if f.startswith(key)), "")


def set_field(obj, key, value):
    for i, f in enumerate(obj):
        if i > 0 and f.startswith(key):
            obj[i] = key + value
            return
    obj.append(key + value)


def bump(obj):
    set_field(obj, "v", str(int(field(obj, "v") or "0") + 1))


def edit(objects, rng, roads=5, deleted=2, added=1, members=1):
    """Moves a node of `roads` roads and of `members` multipolygon member ways, deletes `deleted`
    buildings and adds `added` new ones (20 m squares beside moved nodes). Returns the edited objects
    (versions of changed objects raised by one, as a real edit would) and the number of nodes moved."""
    nodes = {o[0][1:]: o for o in objects if o[0][0] == "n"}
    ways = [o for o in objects if o[0][0] == "w"]
    road_ways = [w for w in ways
                 if re.search(r"(^|,)highway=(residential|secondary|tertiary|primary|service)", field(w, "T"))]
    buildings = [w for w in ways if re.search(r"(^|,)building=", field(w, "T"))]
    member_ids = set()
    for r in (o for o in objects if o[0][0] == "r" and "type=multipolygon" in field(o, "T")):
        member_ids |= {m.split("@")[0][1:] for m in field(r, "M").split(",") if m.startswith("w")}
    member_ways = [w for w in ways if w[0][1:] in member_ids]
    moved = set()
    chosen = rng.sample(road_ways, min(roads, len(road_ways))) + rng.sample(member_ways, min(members, len(member_ways)))
    for w in chosen:
        ref = rng.choice(field(w, "N").split(","))[1:]
        if ref in moved or ref not in nodes:
            continue
        n = nodes[ref]
        set_field(n, "x", f"{float(field(n, 'x')) + 0.0002:.7f}")
        set_field(n, "y", f"{float(field(n, 'y')) + 0.0001:.7f}")
        bump(n)
        moved.add(ref)
    gone = {w[0] for w in rng.sample(buildings, min(deleted, len(buildings)))}
    objects = [o for o in objects if o[0] not in gone]
    # New buildings (20 m squares) beside moved nodes, with ids above every object's.
    top = max(int(o[0][1:]) for o in objects) + 1000
    new_nodes, new_ways = [], []
    for k, ref in enumerate(sorted(moved)[:added]):
        x, y = float(field(nodes[ref], "x")), float(field(nodes[ref], "y"))
        square = [(x + 0.0003, y), (x + 0.00057, y), (x + 0.00057, y + 0.00018), (x + 0.0003, y + 0.00018)]
        base = top + 10 * k
        new_nodes += [[f"n{base + i}", "v1", "dV", f"x{px:.7f}", f"y{py:.7f}"] for i, (px, py) in enumerate(square)]
        refs = ",".join(f"n{base + i}" for i in range(4)) + f",n{base}"
        new_ways.append([f"w{base}", "v1", "dV", "Tbuilding=yes", "N" + refs])
    last_node = max(i for i, o in enumerate(objects) if o[0][0] == "n")
    last_way = max(i for i, o in enumerate(objects) if o[0][0] == "w")
    objects = objects[: last_node + 1] + new_nodes + objects[last_node + 1: last_way + 1] + new_ways + \
        objects[last_way + 1:]
    return objects, len(moved)


def write_opl(path, objects):
    with open(path, "w") as f:
        f.writelines(" ".join(o) + "\n" for o in objects)
