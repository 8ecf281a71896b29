#!/usr/bin/env python3
"""Puts a few frames of a `tree-mech simulate --animate` GIF side by side in one PNG, for the
README: `python3 tools/gif_frames.py anim.gif out.png 0.5 1.5 2.5 3.5` (times in seconds;
frames are 1/25 s apart; `--whole` first keeps each picture's full width, for a wide figure
such as the Solo-12). Needs Pillow (`pip install pillow`)."""
import sys

from PIL import Image

args = sys.argv[1:]
whole = args[0] == "--whole"
source, target, *times = args[1:] if whole else args
gif = Image.open(source)
frames = []
for t in map(float, times):
    gif.seek(min(round(t * 25), gif.n_frames - 1))
    frame = gif.convert("RGB")
    # Keep the middle of the picture, where the figure is, at two thirds of the size.
    w, h = frame.size
    if not whole:
        frame = frame.crop((w // 6, 0, w - w // 6, h))
    scale = 2 if not whole else 1
    frames.append(frame.resize((frame.width * scale // 3, h * scale // 3), Image.LANCZOS))
strip = Image.new("RGB", (sum(f.width for f in frames), frames[0].height), "white")
x = 0
for f in frames:
    strip.paste(f, (x, 0))
    x += f.width
strip.save(target, optimize=True)
print(f"wrote {target}: {len(frames)} frames")
