# Two commands do everything on a fresh machine:
#   make demo   installs into .venv and runs `cpapfit demo`
#   make test   installs into .venv (and Debian's chromium, for the report's browser test, and libusb, for
#               reading a RealSense recording) and runs the test suite
PYTHON ?= python3
CHROMIUM := /usr/bin/chromium
LIBUSB := /usr/share/doc/libusb-1.0-0/copyright
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: install demo test clean

install: $(STAMP)

$(STAMP): pyproject.toml requirements.lock
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --disable-pip-version-check --no-deps -r requirements.lock
	$(PY) -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation -e .
	touch $@

demo: $(STAMP)
	$(VENV)/bin/cpapfit demo

# Two worker processes (pytest-xdist): most tests use one core, and CI has two; tests sharing a costly
# fixture run in one of them (`tests/conftest.py`, SHARED_WORK); the 15 slowest tests listed.
test: $(STAMP) $(CHROMIUM) $(LIBUSB)
	$(PY) -m pytest -q -n 2 --dist loadgroup --durations=15

# Debian's packages the tests need: Chromium, which opens report.html headless (no browser
# download), and libusb, with which pyrealsense2 reads a RealSense recording.
$(CHROMIUM): DEBIAN_PACKAGE := chromium
$(LIBUSB): DEBIAN_PACKAGE := libusb-1.0-0
$(CHROMIUM) $(LIBUSB):
	apt-get update -q
	DEBIAN_FRONTEND=noninteractive apt-get install -y -q $(DEBIAN_PACKAGE)

clean:
	rm -rf $(VENV) cpapfit-demo
