# The two commands of the README. Both set up everything first (idempotent, seconds when done).
RELEASE ?= worldsimprobe
COUNT ?= 12
WORKERS ?= 2

.PHONY: setup release test

setup:
	@bash scripts/setup.sh

release: setup
	@.venv/bin/wsp build --platform maniskill --suite t1 --count $(COUNT) --workers $(WORKERS) --out $(RELEASE)

test: setup
	@bash scripts/test.sh
