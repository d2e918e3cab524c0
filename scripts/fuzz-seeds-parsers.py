#!/usr/bin/env python3
"""Seeds of the fuzz targets pth, pickle, colmap_binary, scannet_text, field_config and pack_zip
(fuzz/corpus/<target>/seed-*): small valid inputs written by hand, as torch.save, COLMAP, ScanNet
and a capture zip lay them out. The checkpoint target's seed comes from
`cargo test --test hostile_input_parsers write_checkpoint_fuzz_seed -- --ignored`.
Usage: python3 scripts/fuzz-seeds-parsers.py (from the repository root)."""
import io
import os
import struct
import zipfile
import zlib

ROOT = "fuzz/corpus"


def write(target, name, data):
    os.makedirs(f"{ROOT}/{target}", exist_ok=True)
    with open(f"{ROOT}/{target}/{name}", "wb") as f:
        f.write(data)


def text(s):
    b = s.encode()
    return b"X" + struct.pack("<I", len(b)) + b


def tensor(key, numel, shape):
    """torch._utils._rebuild_tensor_v2 of a contiguous float32 view of storage `key`."""
    out = b"ctorch._utils\n_rebuild_tensor_v2\n("
    out += b"(" + text("storage") + b"ctorch\nFloatStorage\n" + text(key) + text("cpu")
    out += b"K" + bytes([numel]) + b"tQ"
    strides, acc = [], 1
    for d in reversed(shape):
        strides.insert(0, acc)
        acc *= d
    out += b"K\x00(" + b"".join(b"K" + bytes([d]) for d in shape) + b"t("
    out += b"".join(b"K" + bytes([s]) for s in strides) + b"t\x89ccollections\nOrderedDict\n)Rt"
    return out + b"R"


def state_dict_pickle(names, wrap=None):
    body = b"}("
    for i, n in enumerate(names):
        body += text(n) + tensor(str(i), 16, [4, 4])
    body += b"u"
    if wrap:
        body = b"}(" + text(wrap) + body + b"u"
    return b"\x80\x02" + body + b"."


def png(width, height, value):
    raw = b"".join(b"\x00" + bytes([value, 20, 30]) * width for _ in range(height))

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")


def zipped(entries):
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_STORED) as z:
        for name, data in entries:
            z.writestr(name, data)
    return out.getvalue()


def main():
    # The pickle target zips its input with four 64-byte storages named 0..3.
    write("pickle", "seed-state-dict.pkl", state_dict_pickle(["t0", "t1"]))
    write("pickle", "seed-teacher.pkl", state_dict_pickle(["module.t0", "t1"], "teacher"))
    storages = [(f"archive/data/{i}", struct.pack("<16f", *[float(i)] * 16)) for i in range(2)]
    write("pth", "seed-state-dict.pth", zipped(
        [("archive/data.pkl", state_dict_pickle(["a", "b"])), ("archive/byteorder", b"little")]
        + storages + [("archive/version", b"3\n")]))

    cameras = struct.pack("<QIIQQ", 1, 1, 1, 64, 48) + struct.pack("<4d", 50, 50, 32, 24)
    images = (struct.pack("<QI", 1, 1) + struct.pack("<7d", 1, 0, 0, 0, 0, 0, 0) + struct.pack("<I", 1)
              + b"a.jpg\0" + struct.pack("<Q", 0))
    points = struct.pack("<Q", 0)
    write("colmap_binary", "seed-pinhole.bin", b"--next-file--".join([cameras, images, points]))

    write("scannet_text", "seed-pose.txt", b"1 0 0 0.5\n0 1 0 0\n0 0 1 2\n0 0 0 1\n")
    write("scannet_text", "seed-intrinsics.txt", b"500 0 320 0\n0 500 240 0\n0 0 1 0\n0 0 0 1\n")

    write("field_config", "seed-batch.json", b'{"batch_rays": 256, "adam": {"lr_warmup": 0.01}}')
    write("field_config", "seed-encoding.json", b'{"encoding": {"kind": "hash_only"}, "hash_levels": 4}')

    frame = '{{"file_path": "{}.png", "transform_matrix": [[1, 0, 0, {}], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}}'
    transforms = ('{"fl_x": 8, "fl_y": 8, "cx": 4, "cy": 3, "w": 8, "h": 6, "frames": ['
                  + frame.format("a", 0) + ", " + frame.format("b", 0.5) + "]}")
    write("pack_zip", "seed-transforms.zip", zipped(
        [("cap/transforms.json", transforms.encode()), ("cap/a.png", png(8, 6, 10)), ("cap/b.png", png(8, 6, 200))]))


if __name__ == "__main__":
    main()
