#!/usr/bin/env python3
"""Writes the hand-made part of the fuzz seed corpus (fuzz/corpus/<target>/seed-*): small valid
inputs of every format, so the fuzzer starts from inputs that reach deep into each parser.
Archives come from `scribblefield demo-scene` (pass the binary as the first argument; without it
archive seeds are skipped). Findings are kept beside these as crash-* files. docs/fuzzing.md."""
import io
import json
import os
import struct
import subprocess
import sys
import tempfile
import zipfile
import zlib

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "fuzz", "corpus")


def put(target, name, data):
    d = os.path.join(ROOT, target)
    os.makedirs(d, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    assert len(data) <= 8192, f"{target}/{name}: {len(data)} bytes, keep seeds small"
    with open(os.path.join(d, name), "wb") as f:
        f.write(data)


# ---- labels.json and share links
CLASSES = [("background", [90, 90, 100]), ("table", [170, 110, 50]), ("box", [230, 50, 60])]


def labels(frames):
    return {
        "format": "scribblefield-labels",
        "version": 1,
        "classes": [{"name": n, "color": c} for n, c in CLASSES],
        "frames": [
            {"frame": f, "strokes": [{"class": cls, "radius": r, "points": pts} for cls, r, pts in strokes]}
            for f, strokes in frames
        ],
    }


SIMPLE = [
    (0, [(1, 4.0, [[3.5, 4.5], [10.0, 12.0], [20.0, 8.0]]), (None, 2.0, [[5.0, 5.0]])]),
    (3, [(2, 200.0, [[0.5, 0.5], [63.5, 47.5]]), (0, 1.5, [[-10.0, -10.0], [100.0, 100.0]])]),
]


def varint(v):
    out = bytearray()
    while True:
        b = v & 0x7F
        v >>= 7
        if v:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


def zigzag(v):
    return (v << 1) ^ (v >> 63) if v >= 0 else ((-v) << 1) - 1


def share_code(frames, classes=CLASSES, version=1):
    raw = bytearray([version])
    raw += varint(len(classes))
    for n, c in classes:
        raw += varint(len(n.encode())) + n.encode() + bytes(c)
    raw += varint(len(frames))
    prev = 0
    for f, strokes in frames:
        raw += varint((f - prev) & 0xFFFFFFFF)
        prev = f
        raw += varint(len(strokes))
        for cls, r, pts in strokes:
            raw += varint(0 if cls is None else cls + 1)
            raw += varint(max(1, round(r * 8)))
            raw += varint(len(pts))
            last = [0, 0]
            for p in pts:
                for a in range(2):
                    q = round(p[a] * 8)
                    raw += varint(zigzag(q - last[a]))
                    last[a] = q
    c = zlib.compressobj(9, zlib.DEFLATED, -15)
    packed = c.compress(bytes(raw)) + c.flush()
    import base64
    return base64.urlsafe_b64encode(packed).decode().rstrip("=")


def label_seeds():
    put("labels_json", "seed-simple.json", json.dumps(labels(SIMPLE)))
    put("labels_json", "seed-empty.json", json.dumps(labels([])))
    put("labels_json", "seed-compact.json", json.dumps(labels(SIMPLE), separators=(",", ":")))
    put("labels_json", "seed-duplicate-frame.json", json.dumps(labels([SIMPLE[0], SIMPLE[0]])))
    put("labels_json", "seed-big-radius.json", json.dumps(labels([(1, [(0, 4096.0, [[1.0, 1.0]])])])))
    put("share_link", "seed-simple.txt", share_code(SIMPLE))
    put("share_link", "seed-empty.txt", share_code([]))
    put("share_link", "seed-repeated-frame.txt", share_code([SIMPLE[0], SIMPLE[0]]))
    put("share_link", "seed-many-points.txt", share_code([(1, [(1, 3.0, [[i % 64, i // 64] for i in range(600)])])]))


# ---- .npy
def npy(descr, shape, values_bytes, version=1):
    header = "{'descr': '%s', 'fortran_order': False, 'shape': %s, }" % (descr, repr(tuple(shape)))
    pre = 10 if version == 1 else 12
    pad = (64 - (pre + len(header) + 1) % 64) % 64
    header = header + " " * pad + "\n"
    size = struct.pack("<H", len(header)) if version == 1 else struct.pack("<I", len(header))
    return b"\x93NUMPY" + bytes([version, 0]) + size + header.encode() + values_bytes


def npy_seeds():
    f4 = struct.pack("<24f", *[i * 0.25 for i in range(24)])
    put("npy", "seed-f4-2x3x4.npy", npy("<f4", (2, 3, 4), f4))
    put("npy", "seed-f2-1x2x3.npy", npy("<f2", (1, 2, 3), struct.pack("<6e", *[0.5 * i for i in range(6)])))
    put("npy", "seed-f8-2x2x1.npy", npy("<f8", (2, 2, 1), struct.pack("<4d", 1, 2, 3, 4)))
    put("npy", "seed-v2-f4.npy", npy("<f4", (1, 1, 2), struct.pack("<2f", 1, 2), version=2))
    put("npy", "seed-huge-shape.npy", npy("<f4", (2**32, 2**32, 1), b""))
    put("npy", "seed-fortran.npy", npy("<f4", (1, 2, 1), struct.pack("<2f", 1, 2)).replace(b"False", b"True "))


# ---- safetensors
def safetensors(tensors, metadata=None):
    header = {}
    data = b""
    for name, dtype, shape, raw in tensors:
        header[name] = {"dtype": dtype, "shape": shape, "data_offsets": [len(data), len(data) + len(raw)]}
        data += raw
    if metadata:
        header["__metadata__"] = metadata
    h = json.dumps(header).encode()
    h += b" " * ((8 - len(h) % 8) % 8)
    return struct.pack("<Q", len(h)) + h + data


def safetensors_seeds():
    put("safetensors", "seed-f32.safetensors", safetensors([("w", "F32", [2, 3], struct.pack("<6f", *range(6)))]))
    put(
        "safetensors",
        "seed-mixed.safetensors",
        safetensors(
            [
                ("a.weight", "F16", [2, 2], struct.pack("<4e", 1, 2, 3, 4)),
                ("a.bias", "BF16", [2], b"\x80\x3f\x00\x40"),
                ("b", "F64", [1], struct.pack("<d", 3.5)),
                ("scalar", "F32", [], struct.pack("<f", 1.0)),
            ],
            {"format": "pt"},
        ),
    )
    put("safetensors", "seed-big-shape.safetensors", safetensors([("x", "F32", [2**32, 2**32], b"")]))


# ---- capture text formats
def transforms_seeds():
    m = [[1, 0, 0, 0.5], [0, 1, 0, 0], [0, 0, 1, 2], [0, 0, 0, 1]]
    base = {
        "fl_x": 500.0, "fl_y": 500.0, "cx": 320.0, "cy": 240.0, "w": 640, "h": 480,
        "frames": [
            {"file_path": "images/frame_00001.png", "transform_matrix": m},
            {"file_path": "./images/frame_00002", "transform_matrix": m, "depth_file_path": "depth/00002.png"},
        ],
    }
    put("transforms_json", "seed-nerfstudio.json", json.dumps(base, indent=1))
    angle = {"camera_angle_x": 0.69, "frames": [{"file_path": "./train/r_0", "transform_matrix": m}], "w": 800, "h": 800}
    put("transforms_json", "seed-angle.json", json.dumps(angle))
    distorted = dict(base, camera_model="OPENCV", k1=0.01, k2=-0.002, p1=0.0, p2=0.0)
    put("transforms_json", "seed-distorted.json", json.dumps(distorted))
    per_frame = {"frames": [{"file_path": "a.jpg", "transform_matrix": m[:3], "fl_x": 300, "w": 64, "h": 48}]}
    put("transforms_json", "seed-per-frame.json", json.dumps(per_frame))
    put("transforms_json", "seed-outside.json", json.dumps({"fl_x": 1, "frames": [{"file_path": "../../etc/passwd", "transform_matrix": m}]}))


def colmap_seeds():
    cameras = """# Camera list with one line of data per camera:
#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]
1 PINHOLE 64 48 50 50 32 24
2 SIMPLE_RADIAL 64 48 50 32 24 0.01
3 OPENCV 64 48 50 51 32 24 0.01 -0.001 0.0001 0.0002
4 SIMPLE_PINHOLE 64 48 50 32 24
5 RADIAL 64 48 50 32 24 0.01 0.001
"""
    images = """# Image list with two lines of data per image:
#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME
#   POINTS2D[] as (X, Y, POINT3D_ID)
1 1 0 0 0 0 0 2 1 a.jpg
10 20 1 30 22 2 5 5 -1
2 0.9238795 0 0.3826834 0 -1 0 2 1 sub/b.png
12 20 1 40 22 2

3 0.7071068 0.7071068 0 0 0 1 3 1 c.jpg

"""
    points = """# 3D point list with one line of data per point:
#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)
1 0.1 0.2 0.3 255 0 0 0.5 1 0 2 0
2 -0.5 0.1 1.0 0 255 0 1.2 1 1 2 1
"""
    put("colmap_text", "seed-model.txt", cameras + "\0" + images + "\0" + points)
    put("colmap_text", "seed-one-camera.txt", "1 PINHOLE 64 48 50 50 32 24\n\0" + "1 1 0 0 0 0 0 2 1 a.jpg\n\n\0")
    radial = cameras.replace("1 PINHOLE 64 48 50 50 32 24", "1 OPENCV 64 48 50 51 32 24 0.3 -0.2 0.01 0.02")
    put("colmap_text", "seed-distorted.txt", radial + "\0" + images + "\0" + points)
    put("colmap_text", "seed-outside-name.txt", cameras + "\0" + "1 1 0 0 0 0 0 2 1 ../x.jpg\n\n" + "\0" + points)


def seven_scenes_seeds():
    put("seven_scenes_text", "seed-pose.txt",
        "9.9935108e-001\t-1.3572698e-002\t-3.3386208e-002\t1.5302400e-002\t\n"
        "1.3787472e-002\t9.9990064e-001\t6.2203738e-003\t-4.0082872e-002\t\n"
        "3.3298079e-002\t-6.6739917e-003\t9.9942319e-001\t2.1050371e-002\t\n"
        "0.0000000e+000\t0.0000000e+000\t0.0000000e+000\t1.0000000e+000\t\n")
    put("seven_scenes_text", "seed-pose-3x4.txt", "1 0 0 1\n0 1 0 2\n0 0 1 3\n")
    put("seven_scenes_text", "seed-intrinsics.txt", "585 0 320\n0 585 240\n0 0 1\n")
    put("seven_scenes_text", "seed-intrinsics-4x4.txt", "# ScanNet\n577.6,0,318.9,0\n0,578.7,242.7,0\n0,0,1,0\n0,0,0,1\n")
    put("seven_scenes_text", "seed-tiny-focal.txt", "1e-300 0 320\n0 585 240\n0 0 1\n")


# ---- archives
def archive_seeds(binary):
    with tempfile.TemporaryDirectory() as tmp:
        plain = os.path.join(tmp, "plain.scene.zip")
        feat = os.path.join(tmp, "feat.scene.zip")
        subprocess.run([binary, "demo-scene", "-o", plain, "--size", "16x16", "--frames", "2"], check=True, capture_output=True)
        subprocess.run([binary, "demo-scene", "-o", feat, "--size", "16x16", "--frames", "1", "--features", "baseline"],
                       check=True, capture_output=True)
        put("archive", "seed-demo.scene.zip", open(plain, "rb").read())
        put("archive", "seed-features.scene.zip", open(feat, "rb").read())
        # Stored (uncompressed) and with minified JSON, so mutations reach scene.json directly.
        with zipfile.ZipFile(plain) as z:
            entries = {n: z.read(n) for n in z.namelist()}
        scene = json.loads(entries["scene.json"])
        scene["labels"] = "labels.json"
        entries["scene.json"] = json.dumps(scene, separators=(",", ":")).encode()
        entries["labels.json"] = json.dumps(labels(SIMPLE[:1]), separators=(",", ":")).encode()
        out = io.BytesIO()
        with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as z:
            for n, data in entries.items():
                z.writestr(n, data)
        put("archive", "seed-stored-labels.scene.zip", out.getvalue())
        # The same entries for archive_entries: `--entry:NAME\n` then the bytes.
        put("archive_entries", "seed-labels.entries",
            b"".join(b"--entry:" + n.encode() + b"\n" + d for n, d in entries.items()))
        with zipfile.ZipFile(feat) as z:
            feat_entries = {n: z.read(n) for n in z.namelist()}
        scene = json.loads(feat_entries["scene.json"])
        feat_entries["scene.json"] = json.dumps(scene, separators=(",", ":")).encode()
        put("archive_entries", "seed-features.entries",
            b"".join(b"--entry:" + n.encode() + b"\n" + d for n, d in feat_entries.items()))


if __name__ == "__main__":
    label_seeds()
    npy_seeds()
    safetensors_seeds()
    transforms_seeds()
    colmap_seeds()
    seven_scenes_seeds()
    if len(sys.argv) > 1:
        archive_seeds(sys.argv[1])
    for t in sorted(os.listdir(ROOT)):
        files = os.listdir(os.path.join(ROOT, t))
        print(t, len(files), "files", sum(os.path.getsize(os.path.join(ROOT, t, f)) for f in files), "bytes")
