#!/usr/bin/env python3
"""Instructions per output pixel of the warp's block loops, counted in the disassembly of
src/warp/sample.o: RGB24's (4 pixels per iteration) and the one-channel planes' (8 pixels, 16 on
AVX-512's zmm registers; told apart by their tap loads: 16 bits into a lane, pinsrw on SSE2 and
ld1 {v.h}[i] on NEON, or vpgatherdd on AVX2 and AVX-512). Each loop runs from the branch target
of its 'any pixel outside?' test (pmovmskb on SSE2, vpmovmskb on AVX2, umaxv on NEON, kmovw of
the mask into a register on AVX-512) through that test's branch, header included.
    tools/cross/insns-per-pixel.py OBJDUMP OBJECT      e.g. aarch64-linux-gnu-objdump build-arm64/src/warp/sample.o
"""
import re, subprocess, sys

objdump, obj = sys.argv[1], sys.argv[2]
text = subprocess.run([objdump, "-d", "--no-show-raw-insn", obj], check=True, capture_output=True, text=True).stdout
insns = []
for fn in re.findall(r"<(?:warp_sample_row|sample_row_gray\w*)>:\n(.*?)(?:\n\n|\Z)", text, re.S):
    for line in fn.splitlines():
        m = re.match(r"\s*([0-9a-f]+):\s+(\S+)\s*(.*)", line)
        if m:
            insns.append((int(m.group(1), 16), m.group(2), m.group(3)))
for check, (_, op, _a) in enumerate(insns):
    if op not in ("pmovmskb", "vpmovmskb", "umaxv") and not (op == "kmovw" and re.search(r",%e", _a)):
        continue
    branch = next(i for i in range(check, len(insns))
                  if re.match(r"(j[a-z]+|b\.[a-z]+|cbn?z|tbn?z)$", insns[i][1]))
    target = int(re.search(r"\b([0-9a-f]+) <", insns[branch][2]).group(1), 16)
    loop = [x for x in insns if target <= x[0] <= insns[branch][0]]
    if not loop:  # a forward branch: a test on the way out of a loop, not a loop's own
        continue
    ops = {}
    for _, o, _a in loop:
        ops[o] = ops.get(o, 0) + 1
    gray = any(o in ("pinsrw", "vpgatherdd") or (o == "ld1" and "}[" in a) for _, o, a in loop)
    wide = any("zmm" in a for _, _o, a in loop)
    pixels = (16 if wide else 8) if gray else 4
    name = (("one channel, AVX-512" if wide else "one channel, AVX2") if "vpgatherdd" in ops
            else "one channel") if gray else "RGB24"
    print(f"{obj}, {name}: {len(loop)} instructions per {pixels} pixels"
          f" = {len(loop) / pixels:.2f} per pixel")
    print("  " + ", ".join(f"{o} {n}" for o, n in sorted(ops.items(), key=lambda t: -t[1])))
