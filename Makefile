# Every command the README mentions lives here. `make run` and `make test` are the README's first two.
.PHONY: run test setup build bench bench-criterion bench-process bench-nats shutdown-save soak fmt lint ci fixtures conformance fuzz reproduce

CARGO ?= cargo
RUN_FIXTURE ?= tests/fixtures/robot/recorded_run.lp

# The main job on its bundled default: the robot monitors over the recorded-run fixture, their
# verdicts and actions (no pass-through), then a short summary (steps, violations per property,
# augmented actions and why, final MSE). `make run PASSTHROUGH=1` echoes every record as well.
run: build
	./target/release/tessla-telegraf run $(if $(PASSTHROUGH),,--no-passthrough) < $(RUN_FIXTURE) > target/run.lp
	cat target/run.lp
	./target/release/tessla-telegraf report --summary target/run.lp

build:
	$(CARGO) build --release

setup:
	bash tools/setup.sh

# The test command (also what .ci/run calls).
test: setup
	$(CARGO) test --workspace

# Benchmarks; figures in BENCHMARKS.md. Criterion guards of the hot paths (codec, binding, engine
# step, output formatting, whole record path), then the whole-process runs against the baselines
# (cat, parse-only, Python, rtlola-cli; workloads generated once into target/bench-data) with
# latency, peak RSS and spec load, written to target/bench-results.md.
CRITERION_ARGS ?= --noplot --warm-up-time 1 --measurement-time 3
BENCH_REPS ?= 5

bench: bench-criterion bench-process

bench-criterion:
	$(CARGO) bench -p lineproto --bench codec -- $(CRITERION_ARGS)
	$(CARGO) bench --bench engine --bench binding --bench encode --bench record_path --bench library -- $(CRITERION_ARGS)

bench-process:
	python3 bench/run.py --reps $(BENCH_REPS)

# Fleet on NATS (BENCHMARKS.md, "Fleet on NATS"): throughput with 1, 2 and 4 partitions and the
# standby's takeover time, on a 3-node nats-server cluster started on free loopback ports.
bench-nats: build
	$(CARGO) run --release --example fleet_nats -- --robots 64 --reps 3

# Shutdown with --state (README, "Restarts and reloads"): from stdin closed (how Telegraf stops
# the child) to exit with N robot instances to save, 5 runs each, medians; Telegraf's budget is
# 5 s to SIGTERM and 5 more to SIGKILL (Windows: a kill after 5 s). SHUTDOWN_ARGS="--nats
# HOST:PORT,... --nats-options replicas=3" saves to a JetStream bucket instead of a file.
SHUTDOWN_INSTANCES ?= 10000 50000 100000
shutdown-save: build
	python3 bench/shutdown_save.py --instances $(SHUTDOWN_INSTANCES) --reps 5 $(SHUTDOWN_ARGS)

# Soak test (not in CI): 10 million fleet records (1,000 robots) through the release binary with
# --instance-by robot, RSS sampled every second; fails unless memory stays flat after warm-up.
soak: build
	python3 bench/soak.py

fmt:
	$(CARGO) fmt --all

lint:
	$(CARGO) clippy --workspace --all-targets -- -D warnings
	$(CARGO) clippy --workspace --all-targets --no-default-features -- -D warnings

ci:
	bash .ci/run

# Build every cargo-fuzz target and run each for FUZZ_SECONDS (default 60); fails on a crash.
# Long runs and their findings: RELIABILITY.md.
fuzz:
	bash tools/fuzz-ci.sh

# Regenerate the recorded-run fixture and its ground truth (fixed seed).
fixtures:
	python3 tools/gen_robot_run.py

# Rewrite the conformance pass list after an improvement (the list may only grow).
conformance:
	UPDATE_CONFORMANCE=1 $(CARGO) test -p tessla-trace --test conformance -- --nocapture
	cat target/conformance-summary.txt

# Rewrite the standard-library and user-spec pass lists (tests/stdlib.rs)
# and the prelude's (tests/prelude.rs)
# after an improvement; the lists may only grow.
.PHONY: stdlib
stdlib:
	UPDATE_STDLIB=1 $(CARGO) test --test stdlib -- --nocapture
	UPDATE_STDLIB=1 $(CARGO) test --test prelude -- --nocapture
	grep -h 'pass$$' target/stdlib-summary.txt target/prelude-summary.txt

# The README's example image, from the recorded-run fixture.
report-example: build
	./target/release/tessla-telegraf run < tests/fixtures/robot/recorded_run.lp > target/out.lp
	./target/release/tessla-telegraf report target/out.lp -o target/report
	mkdir -p docs && cp target/report/speeds.svg docs/report-example.svg

# The paper's Table I in simulation: the bundled yoga-mat scenario with the monitor off and on,
# sweeps over 20 seeds and a few gain/delta values; writes docs/reproduction.md and its plots.
reproduce: build
	nice -n 10 python3 tools/reproduce.py target/release/tessla-telegraf
