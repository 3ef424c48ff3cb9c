"""Code shared by the plant, the flight software and the ground tools: attitude math,
frames, atmosphere models, data-file loading, and the runtime helpers every process uses
(rt.py). Nothing here knows about transports, and nothing imports fsw/, sim/ or gse/."""
from . import jitcache as _jitcache

_jitcache.configure()
