#!/usr/bin/env bash
# GGUI (the window and the offscreen frames) needs a Vulkan device. Without a GPU, Mesa's
# software rasteriser (lavapipe) is one. Install it where it is missing and we may; otherwise
# say what to install. Never fails the caller: headless runs work with --no-images.
set -u
have_vulkan() {
  ldconfig -p 2>/dev/null | grep -q 'libvulkan.so.1' && ls /usr/share/vulkan/icd.d/*.json >/dev/null 2>&1
}
if have_vulkan; then
  command -v xvfb-run >/dev/null 2>&1 || [ "$(id -u)" != 0 ] || \
    (apt-get install -y -qq xvfb >/dev/null 2>&1 || true)
  exit 0
fi
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "loom: no Vulkan driver found; installing mesa-vulkan-drivers libvulkan1 xvfb (apt)" >&2
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq >/dev/null && \
    apt-get install -y -qq mesa-vulkan-drivers libvulkan1 xvfb >/dev/null && exit 0
  echo "loom: apt-get could not install the Vulkan packages; rendering will be skipped" >&2
  exit 0
fi
echo "loom: no Vulkan driver found. For windows and PNG frames install one, e.g. on Debian:" >&2
echo "      sudo apt-get install mesa-vulkan-drivers libvulkan1 xvfb" >&2
echo "      (until then use --no-images; rendering tests are skipped)" >&2
exit 0
