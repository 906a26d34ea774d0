"""Prints how many iterations of a 100000-iteration loop one serial kernel runs on Vulkan:
100000 on a GPU driver, at most 65535 on Mesa's llvmpipe (lavapipe), which caps loops
(cloth/strain/direct.py LOOP_CAP). Run as a script by tests/test_vulkan.py."""
import sys

import taichi as ti


@ti.kernel
def count(n: int) -> int:
    ti.loop_config(serialize=True)
    total = 0
    for _ in range(1):
        for _i in range(n):
            total += 1
    return total


if __name__ == "__main__":
    ti.init(arch=ti.vulkan, log_level=ti.ERROR)
    print(count(int(sys.argv[1]) if len(sys.argv) > 1 else 100000))
