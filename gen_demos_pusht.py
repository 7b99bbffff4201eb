"""Generate PushT expert demos as a local LeRobot v3 dataset.

    python gen_demos_pusht.py --episodes 50 --seed 0 --out outputs/demos/pusht [--noise 0.0] [--video]

observation.state float32[10] and action float32[2] (pusher velocity, m/s), fps 10; names and
units in pusht_env.py. Callable from Python as main(argv).
"""

import sys

if __name__ == "__main__":
    from ch37.process import headless_gl

    headless_gl()  # --video renders headless: before the imports below load mujoco

import gen_demos
from datagen import PUSHT  # the task: its env, its expert, its name (the engine reads the same)


def main(argv=None) -> int:
    return gen_demos.main(PUSHT, argv)


if __name__ == "__main__":
    sys.exit(main())
