# GroundSieve: `make demo` and `make test` work on a fresh Debian 12 machine (as root: QGIS
# is installed from apt on first use); both are quick the second time.
PY := .venv/bin/python
VERSION := $(shell sed -n 's/^version=//p' metadata.txt)

.PHONY: env demo test test-core zip bench clean

env:
	@scripts/bootstrap

demo: env
	$(PY) scripts/demo.py --out out

test: env
	$(PY) -m pytest -q -ra

test-core: env
	$(PY) -m pytest -q -ra tests/core

zip:
	@mkdir -p dist
	git archive --format=zip --prefix=groundsieve/ -o dist/groundsieve-$(VERSION).zip HEAD
	@echo "dist/groundsieve-$(VERSION).zip"

bench: env
	$(PY) bench/isprs.py --filter smrf --data ../shared/data/isprs --params ../shared/data/isprs/isprs_smrf_settings.txt
	$(PY) bench/isprs.py --filter smrf --data ../shared/data/isprs
	$(PY) bench/speed.py

clean:
	rm -rf .build out dist
