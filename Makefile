# GroundSieve: `make demo` and `make test` work on a fresh Debian 12 machine (as root: QGIS
# is installed from apt on first use); both are quick the second time.
PY := .venv/bin/python
VERSION := $(shell sed -n 's/^version=//p' metadata.txt)

.PHONY: env demo test test-core test-desktop test-qgis340 screenshots zip bench clean

# The plugin tests run on Debian 12's QGIS 3.22 (the system's) and again on QGIS 3.40 LTR from
# bookworm-backports, unpacked beside it by scripts/qgis-340. The installer test needs the
# system's bare Python, so it runs in the first pass only.
QGIS340_ONLY := --deselect tests/plugin/test_dependencies.py::test_installer_puts_the_packages_into_a_bare_qgis_python_and_the_algorithms_run

env:
	@scripts/bootstrap

demo: env
	$(PY) scripts/demo.py --out out

test: env
	$(PY) -m pytest -q -ra
	@$(MAKE) --no-print-directory test-qgis340

test-qgis340: env
	@scripts/qgis-340
	env $$(scripts/qgis-340 --env) GROUNDSIEVE_EXPECT_QGIS=3.40 $(PY) -m pytest -q -ra tests/plugin $(QGIS340_ONLY)

test-core: env
	$(PY) -m pytest -q -ra tests/core

# The real desktop dialogs on a virtual display (Xvfb): cancel at every stage, progress over a run,
# on a generated 5 M point cloud (about 90 s; part of `make test` through tests/desktop).
test-desktop: env
	$(PY) -m pytest -q -ra tests/desktop

# docs/img/*.png: every algorithm's dialog, from the real QGIS dialogs (about 30 s)
screenshots: env
	scripts/screenshots

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
