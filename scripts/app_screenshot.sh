#!/usr/bin/env bash
# The README's window screenshot (docs/screenshot.png): the default scene in the GGUI window on
# a virtual X display, grabbed whole (panel and read-out included; the app's own screenshot
# holds the 3-D scene only). Needs Xvfb (make vulkan installs it) and the venv.
#   bash scripts/app_screenshot.sh [seconds=75] [out=docs/screenshot.png] [scene args...]
# SCREEN=WxH sets the virtual screen (default the README's 1280x800; the window fits it).
set -euo pipefail
wait_s=${1:-75}; out=${2:-docs/screenshot.png}; shift 2 || true
display=:97
Xvfb $display -screen 0 ${SCREEN:-1280x800}x24 >/dev/null 2>&1 &
xvfb=$!
trap 'kill $app $xvfb 2>/dev/null || true' EXIT
sleep 2
DISPLAY=$display LOOM_APP_FRAMES=100000 .venv/bin/python main.py "${@:-hanging}" >/dev/null 2>&1 &
app=$!
sleep "$wait_s"
DISPLAY=$display .venv/bin/python - "$out" <<'PY'
import sys
from PIL import ImageGrab
shot = ImageGrab.grab(xdisplay=":97")
box = shot.getbbox()
if box is None:
    sys.exit("app_screenshot: the display is black (the window had not opened yet): wait longer")
shot.crop(box).save(sys.argv[1])
print(f"app_screenshot: {sys.argv[1]} {box[2] - box[0]}x{box[3] - box[1]}")
PY
