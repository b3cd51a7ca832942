# The two commands of the README. Both set up everything first (idempotent, seconds when done).
RELEASE ?= worldsimprobe
CALIBRATION ?= calibration
WORKERS ?= 2
T1 ?= 8
T2 ?= 8
T3 ?= 8
T4 ?= 6
T5 ?= 8
WSP = .venv/bin/wsp

.PHONY: setup release test

setup:
	@bash scripts/setup.sh

# Build a small ManiSkill release of every suite (T3: one group of eight sources), write every calibration baseline, score each, print the table.
release: setup
	@$(WSP) build --platform maniskill --suite t1 --count $(T1) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform maniskill --suite t2 --count $(T2) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform maniskill --suite t3 --count $(T3) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform maniskill --suite t4 --count $(T4) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform maniskill --suite t5 --count $(T5) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) calibrate --release $(RELEASE) --out $(CALIBRATION) --workers $(WORKERS)

test: setup
	@bash scripts/test.sh
