"""``python -m interfaces.mavlink.signing new-key PATH`` (or ``check-key [PATH]``)."""
from .keys import main

if __name__ == "__main__":
    raise SystemExit(main())
