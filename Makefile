# Every command the README mentions lives here. `make run` and `make test` are the README's first two.
.PHONY: run test setup build bench fmt lint ci fixtures conformance reproduce

CARGO ?= cargo
RUN_FIXTURE ?= tests/fixtures/robot/recorded_run.lp

# The main job on its bundled default: the robot monitors over the recorded-run fixture.
run: build
	./target/release/tessla-telegraf < $(RUN_FIXTURE)

build:
	$(CARGO) build --release

setup:
	bash tools/setup.sh

# The test command (also what .ci/run calls).
test: setup
	$(CARGO) test --workspace

# Engine benchmarks (criterion); figures in BENCHMARKS.md.
bench:
	$(CARGO) bench --bench engine -- --noplot

fmt:
	$(CARGO) fmt --all

lint:
	$(CARGO) clippy --workspace --all-targets -- -D warnings

ci:
	bash .ci/run

# Regenerate the recorded-run fixture and its ground truth (fixed seed).
fixtures:
	python3 tools/gen_robot_run.py

# Rewrite the conformance pass list after an improvement (the list may only grow).
conformance:
	UPDATE_CONFORMANCE=1 $(CARGO) test --test conformance -- --nocapture
	cat target/conformance-summary.txt

# The README's example image, from the recorded-run fixture.
report-example: build
	./target/release/tessla-telegraf run < tests/fixtures/robot/recorded_run.lp > target/out.lp
	./target/release/tessla-telegraf report target/out.lp -o target/report
	mkdir -p docs && cp target/report/speeds.svg docs/report-example.svg

# The paper's Table I in simulation: the bundled yoga-mat scenario with the monitor off and on,
# sweeps over 20 seeds and a few gain/delta values; writes docs/reproduction.md and its plots.
reproduce: build
	nice -n 10 python3 tools/reproduce.py target/release/tessla-telegraf
