# The two commands of the README. Both set up everything first (idempotent, seconds when done).
RELEASE ?= worldsimprobe
CALIBRATION ?= calibration
WORKERS ?= 2
T1 ?= 8
T2 ?= 8
T3 ?= 8
T4 ?= 6
T5 ?= 8
# LIBERO: every suite on four of its 40 tasks (a can, a flat box, two bowls; push and tap need a low target)
LIBERO_TASKS ?= libero_object/pick_up_the_alphabet_soup_and_place_it_in_the_basket \
	libero_object/pick_up_the_butter_and_place_it_in_the_basket \
	libero_spatial/pick_up_the_black_bowl_from_table_center_and_place_it_on_the_plate \
	libero_90/KITCHEN_SCENE1_put_the_black_bowl_on_the_plate
LT1 ?= 4
LT2 ?= 4
LT3 ?= 8
LT4 ?= 3
LT5 ?= 4
# ALOHA (two arms): T1, T2, T4 and T5 over its 8 tasks, T3 over its five T3 tasks (one group of eight sources)
AT1 ?= 4
AT2 ?= 4
AT3 ?= 8
AT4 ?= 3
AT5 ?= 8
# ALOHA's T5 on the peg task first: there a push stays in sight of the top camera (the hand hides a pushed cube)
ALOHA_T5_TASKS ?= peg_insertion transfer_cube lift_cube
WSP = .venv/bin/wsp

.PHONY: setup release test

setup:
	@bash scripts/setup.sh

# Build a small release: every suite on ManiSkill, on LIBERO and on ALOHA (T3: one group of eight sources each);
# write every calibration baseline, score each, print the table.
release: setup
	@$(WSP) build --platform maniskill --suite t1 --count $(T1) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform maniskill --suite t2 --count $(T2) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform maniskill --suite t3 --count $(T3) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform maniskill --suite t4 --count $(T4) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform maniskill --suite t5 --count $(T5) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform libero --suite t1 --count $(LT1) --tasks $(LIBERO_TASKS) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform libero --suite t2 --count $(LT2) --tasks $(LIBERO_TASKS) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform libero --suite t3 --count $(LT3) --tasks $(LIBERO_TASKS) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform libero --suite t4 --count $(LT4) --tasks $(LIBERO_TASKS) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform libero --suite t5 --count $(LT5) --tasks $(LIBERO_TASKS) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform aloha --suite t1 --count $(AT1) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform aloha --suite t2 --count $(AT2) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform aloha --suite t3 --count $(AT3) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform aloha --suite t4 --count $(AT4) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) build --platform aloha --suite t5 --count $(AT5) --tasks $(ALOHA_T5_TASKS) --workers $(WORKERS) --out $(RELEASE)
	@$(WSP) calibrate --release $(RELEASE) --out $(CALIBRATION) --workers $(WORKERS)

test: setup
	@bash scripts/test.sh
