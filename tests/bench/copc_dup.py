#!/usr/bin/env python3
"""copc_dup.py — a larger COPC test file for bench_copc.sh, made without a COPC writer.

    copc_dup.py IN.copc.laz OUT.copc.laz N1 N2

Copies IN and appends a new root hierarchy page (the COPC info VLR's root offset and size are
patched to it): IN's level-0 node, then N1 level-1 nodes and N2 level-2 nodes that all point to
that same root chunk (a LAZ chunk decodes on its own, wherever it is referenced from). The
LAZ chunk table and the header are IN's, so a full read still gives IN's points; only the
COPC hierarchy is larger: pc_read_copc_budget decodes the root chunk 1 + N1 (+ N2) times,
which is what a file with that many top-level points costs to read. The duplicated points
lie on top of each other: the image is IN's root, the timing a larger file's."""
import struct
import sys


def main():
    src, dst, n1, n2 = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    if not (0 <= n1 <= 8 and 0 <= n2 <= 64):
        sys.exit("copc_dup: N1 in 0..8, N2 in 0..64")
    data = bytearray(open(src, "rb").read())
    header_size = struct.unpack_from("<H", data, 94)[0]
    user_id = bytes(data[header_size + 2:header_size + 18]).rstrip(b"\0")
    record_id = struct.unpack_from("<H", data, header_size + 18)[0]
    if user_id != b"copc" or record_id != 1:
        sys.exit("copc_dup: %s: the first VLR is not copc/1" % src)
    info = header_size + 54
    root_off, root_size = struct.unpack_from("<QQ", data, info + 40)
    root = None
    for i in range(root_size // 32):
        lv, x, y, z, off, nbytes, count = struct.unpack_from("<iiiiQii", data, root_off + 32 * i)
        if lv == 0:
            root = (off, nbytes, count)
    if root is None:
        sys.exit("copc_dup: no level-0 entry in the root page")
    entries = [(0, 0, 0, 0) + root]
    for k in range(n1):
        entries.append((1, k & 1, (k >> 1) & 1, (k >> 2) & 1) + root)
    for k in range(n2):
        entries.append((2, k & 3, (k >> 2) & 3, (k >> 4) & 3) + root)
    page = b"".join(struct.pack("<iiiiQii", *e) for e in entries)
    new_off = len(data)
    data += page
    struct.pack_into("<QQ", data, info + 40, new_off, len(page))
    open(dst, "wb").write(data)
    print("%s: %d nodes, top levels %d + %d x %d (+ %d x %d) points" %
          (dst, len(entries), root[2], n1, root[2], n2, root[2]))


main()
