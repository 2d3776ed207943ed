# Every command the README mentions lives here. `make run` and `make test` are the README's first two.
.PHONY: run test setup build bench check-spec fmt lint ci

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

bench: build
	$(CARGO) bench --workspace

fmt:
	$(CARGO) fmt --all

lint:
	$(CARGO) clippy --workspace --all-targets -- -D warnings

ci:
	bash .ci/run
