"""Each pytest process on a DDS domain of its own: claimed with an flock on the same lock files
as the C++ tests (/tmp/cpm_test_domains), held while the process lives, and exported as
CPM_DOMAIN_ID before cpm creates a participant."""
import fcntl
import os

import pytest

_held = []


def claim_domain():
    os.makedirs("/tmp/cpm_test_domains", exist_ok=True)
    start = os.getpid() % 232
    for i in range(232):
        candidate = 1 + (start + i) % 232
        f = open(f"/tmp/cpm_test_domains/{candidate}.lock", "w")
        try:
            fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            f.close()
            continue
        _held.append(f)
        return candidate
    raise RuntimeError("no free DDS domain id in 1..232 for this test process")


os.environ["CPM_DOMAIN_ID"] = str(claim_domain())


@pytest.fixture
def extra_domain():
    """One more domain of this process's own (a controller's, say)."""
    return claim_domain()


def wait_until(condition, timeout=5.0):
    import time
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if condition():
            return True
        time.sleep(0.01)
    return condition()
