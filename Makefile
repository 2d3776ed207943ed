# Every command the README mentions lives here. `make run` and `make test` are the README's first two.
.PHONY: run test setup build book cli-md book-pictures install install-files deb profiling readme-run bench bench-criterion bench-process bench-nats bench-fleet bench-telegraf shutdown-save rollout-bench soak fmt lint ci fixtures conformance fuzz reproduce combinations crates-package

CARGO ?= cargo
RUN_FIXTURE ?= tests/fixtures/robot/recorded_run.lp

# The main job on its bundled default: the robot monitors over the recorded-run fixture. The full
# line protocol (verdicts and actions; with PASSTHROUGH=1 every record too) goes to target/run.lp;
# the screen gets what a person reads: when each verdict changed, the augmented actions with their
# reasons, and the summary (`report --timeline --summary`).
run: build
	@./target/release/tessla-telegraf run --log-level warn $(if $(PASSTHROUGH),,--no-passthrough) < $(RUN_FIXTURE) > target/run.lp
	@./target/release/tessla-telegraf report --timeline --summary target/run.lp
	@echo "full line protocol ($$(wc -l < target/run.lp) lines, as Telegraf gets it): target/run.lp"

build:
	$(CARGO) build --release

# Rewrite the README's `make run` block and the command outputs it shows with what the binary
# prints now (after a change to the bundled spec or the fixture; tests/cli/first_hour.rs and
# tests/cli/readme_commands.rs check that they agree).
readme-run: build
	$(MAKE) -s run > target/make-run.txt
	python3 tools/readme_run_block.py target/make-run.txt

setup:
	bash tools/setup.sh

# The book (docs/book, mdBook; tools/setup.sh installs the pinned mdbook) into target/book: open
# target/book/index.html. `make test` builds it too, checks every internal link and anchor, runs
# its shell blocks and opens it in headless Chromium (tests/cli/book.rs).
book:
	mdbook build docs/book

# The book's command-line chapter, made from the command line like the man page.
cli-md: build
	./target/release/tessla-telegraf cli-markdown > docs/book/src/cli.md

# The book's pictures of `report`'s page and of one plot (headless Chromium).
book-pictures: build
	bash tools/book_pictures.sh ./target/release/tessla-telegraf

# The test command (also what .ci/run calls). Suites that need TeSSLa's conformance cases skip
# without them; tools/test-skips.sh then prints loudly which were skipped, why, and how to get
# the cases (a skip never passes in silence).
SKIP_DIR = $${CARGO_TARGET_DIR:-target}/tmp/skipped-suites

test: setup
	@rm -rf $(SKIP_DIR)
	$(CARGO) test --workspace; status=$$?; bash tools/test-skips.sh $(SKIP_DIR); exit $$status

# Install the release binary, its man page and shell completions under PREFIX (DESTDIR for
# staging): PREFIX/bin, PREFIX/share/man/man1, PREFIX/share/{bash-completion,zsh,fish}, and the
# Telegraf systemd drop-in (telegraf/systemd/tessla-telegraf.conf) with the binary's path under
# PREFIX written in, to SYSTEMDDIR/telegraf.service.d (PREFIX/lib/systemd/system: systemd reads
# /usr/lib and /usr/local/lib; for another PREFIX, SYSTEMDDIR=/etc/systemd/system). Then
# `systemctl daemon-reload`. `install-files` does the same without building first (BIN=...).
PREFIX ?= /usr/local
SYSTEMDDIR ?= $(PREFIX)/lib/systemd/system
BIN = ./target/release/tessla-telegraf

install: build
	$(MAKE) install-files

install-files:
	install -d $(DESTDIR)$(PREFIX)/bin $(DESTDIR)$(PREFIX)/share/man/man1 \
	  $(DESTDIR)$(PREFIX)/share/bash-completion/completions \
	  $(DESTDIR)$(PREFIX)/share/zsh/site-functions \
	  $(DESTDIR)$(PREFIX)/share/fish/vendor_completions.d \
	  $(DESTDIR)$(PREFIX)/share/tessla-telegraf \
	  $(DESTDIR)$(SYSTEMDDIR)/telegraf.service.d
	install -m 755 $(BIN) $(DESTDIR)$(PREFIX)/bin/tessla-telegraf
	$(BIN) manpage > $(DESTDIR)$(PREFIX)/share/man/man1/tessla-telegraf.1
	$(BIN) completions bash > $(DESTDIR)$(PREFIX)/share/bash-completion/completions/tessla-telegraf
	$(BIN) completions zsh > $(DESTDIR)$(PREFIX)/share/zsh/site-functions/_tessla-telegraf
	$(BIN) completions fish > $(DESTDIR)$(PREFIX)/share/fish/vendor_completions.d/tessla-telegraf.fish
	install -m 644 specs/telegraf.tessla $(DESTDIR)$(PREFIX)/share/tessla-telegraf/telegraf.tessla
	sed 's|/usr/bin/tessla-telegraf|$(PREFIX)/bin/tessla-telegraf|g' telegraf/systemd/tessla-telegraf.conf \
	  > $(DESTDIR)$(SYSTEMDDIR)/telegraf.service.d/tessla-telegraf.conf
	@echo "installed; with systemd: systemctl daemon-reload"

# The Debian package (cargo-deb; `cargo install cargo-deb` once): the binary, man page, shell
# completions, telegraf.tessla, the sample confs, dashboards, examples and docs, and any
# Telegraf systemd drop-in under telegraf/systemd/. Writes target/debian/tessla-telegraf_*.deb.
deb: build
	bash tools/deb-assets.sh $(BIN) target/deb-assets
	$(CARGO) deb --no-build

# A release build that keeps debug info, for perf and valgrind --tool=callgrind:
# target/profiling/tessla-telegraf (the release profile carries none).
profiling:
	$(CARGO) build --profile profiling

# Benchmarks; figures in the book's Benchmarks chapter. Criterion guards of the hot paths (codec, binding, engine
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

# The fleet level (docs/fleet.md, the Benchmarks chapter, "Fleet level"): cost per record at 1k and 10k
# robots, memory per robot, the closest pair at 1k, 10k and 100k robots; then the fleet checkpoint on a
# nats-server (bench/fleet_checkpoint.py): its bytes per robot, how long it holds the step loop, write and
# read times, memory per robot. FLEET_BASELINE=BINARY (an earlier build) is measured in the same run.
FLEET_BASELINE ?=
bench-fleet: build
	nice -n 5 python3 bench/fleet.py --reps 3 --bin $(or $(CARGO_TARGET_DIR),target)/release/tessla-telegraf
	nice -n 5 python3 bench/fleet_checkpoint.py --bin $(or $(CARGO_TARGET_DIR),target)/release/tessla-telegraf $(if $(FLEET_BASELINE),--baseline $(FLEET_BASELINE))

# Fleet on NATS (the Benchmarks chapter, "Fleet on NATS"): throughput with 1, 2 and 4 partitions and the
# standby's takeover time, on a 3-node nats-server cluster started on free loopback ports.
bench-nats: build
	$(CARGO) run --release --example fleet_nats -- --robots 64 --reps 3

# Robot to action through the real Telegraf (the Benchmarks chapter, "Robot to action"):
# first P2 inside one Telegraf, ours (processors.execd, echo and clone wirings) against the same
# P2 in processors.starlark (bench/p2.star), paired: CPU per record above the no-processor floor
# (bench/telegraf_p2.py); then the delay from a robot's MQTT publish to its action on its topic,
# through Mosquitto, Telegraf (tools/build-telegraf.sh) running the shipped conf and the release
# binary, p50/p90/p99 at 5 Hz: 1 robot on Mosquitto's default (Nagle on) and with
# set_tcp_nodelay (as shipped), then 1 robot (telegraf.conf) and 1,000 (telegraf-fleet.conf),
# with and without the lidar.
DELAY_ROBOTS ?= 1 1000
DELAY_SECONDS ?= 30
P2_RECORDS ?= 200000
P2_REPS ?= 5
bench-telegraf: build
	bash tools/build-telegraf.sh
	python3 bench/telegraf_p2.py --records $(P2_RECORDS) --reps $(P2_REPS)
	$(CARGO) build --release --example telegraf_delay
	./target/release/examples/telegraf_delay --robots 1 --seconds $(DELAY_SECONDS) --warmup 5 --tcp-nodelay off
	for r in $(DELAY_ROBOTS); do \
	  ./target/release/examples/telegraf_delay --robots $$r --seconds $(DELAY_SECONDS) --warmup 5; \
	  ./target/release/examples/telegraf_delay --robots $$r --seconds $(DELAY_SECONDS) --warmup 5 --no-lidar; \
	done

# Shutdown with --state (README, "Restarts and reloads"): from stdin closed (how Telegraf stops
# the child) to exit with N robot instances to save, 5 runs each, medians; Telegraf's budget is
# 5 s to SIGTERM and 5 more to SIGKILL (Windows: a kill after 5 s). SHUTDOWN_ARGS="--nats
# HOST:PORT,... --nats-options replicas=3" saves to a JetStream bucket instead of a file.
SHUTDOWN_INSTANCES ?= 10000 50000 100000
ROLLOUT_REPS ?= 10
# Spec rollouts (the Benchmarks chapter, "Spec versions across a fleet"): publish -> both partitions of a
# two-process fleet running the new version, and no record lost or judged by a mix of versions.
rollout-bench: build
	python3 bench/spec_rollout.py --reps $(ROLLOUT_REPS)

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

# The combination test with more schedules than `make test` runs (README, "Tests and TeSSLa's
# suite"): SEEDS schedules (default 2000), seeds 0 to SEEDS-1; a failure prints its seed.
SEEDS ?= 2000
combinations:
	COMBINATION_SEEDS=$(SEEDS) $(CARGO) test --release --test integration cli::combinations -- --nocapture

# Build every cargo-fuzz target and run each for FUZZ_SECONDS (default 60); fails on a crash.
# Long runs and their findings: docs/book/src/reliability-record.md.
fuzz:
	bash tools/fuzz-ci.sh

# Regenerate the recorded-run fixture and its ground truth (fixed seed).
fixtures:
	python3 tools/gen_robot_run.py

# Rewrite the conformance pass list after an improvement (the list may only grow).
conformance:
	UPDATE_CONFORMANCE=1 $(CARGO) test -p tessla-trace --test conformance -- --nocapture
	cat target/conformance-summary.txt

# Rewrite the standard-library and user-spec pass lists (tests/cli/stdlib.rs)
# and the prelude's (tests/cli/prelude.rs)
# after an improvement; the lists may only grow.
.PHONY: stdlib
stdlib:
	UPDATE_STDLIB=1 $(CARGO) test --test integration cli::stdlib:: -- --nocapture
	UPDATE_STDLIB=1 $(CARGO) test --test integration cli::prelude:: -- --nocapture
	grep -h 'pass$$' target/stdlib-summary.txt target/prelude-summary.txt

# The book's example image (pipeline.md), from the recorded-run fixture.
report-example: build
	./target/release/tessla-telegraf run < tests/fixtures/robot/recorded_run.lp > target/out.lp
	./target/release/tessla-telegraf report target/out.lp -o target/report
	mkdir -p docs/book/src/images && cp target/report/speeds.svg docs/book/src/images/report-example.svg

# The paper's Table I in simulation: the bundled yoga-mat scenario with the monitor off and on,
# sweeps over 20 seeds and a few gain/delta values; writes docs/book/src/reproduction.md and its plots.
reproduce: build
	nice -n 10 python3 tools/reproduce.py target/release/tessla-telegraf

# A refactor's guard: everything the engine prints (`run` on the fixture and bench workloads,
# `trace` on the conformance suite and fixtures, `check`/`check --ir` of every shipped spec),
# compared byte for byte with an older binary: make outputs-compare BASE=path/to/old/binary
OUT_TARGET = $(or $(CARGO_TARGET_DIR),$(CURDIR)/target)
outputs-compare: build
	bash tools/outputs.sh $(BASE) $(OUT_TARGET)/outputs-base
	bash tools/outputs.sh $(OUT_TARGET)/release/tessla-telegraf $(OUT_TARGET)/outputs-new
	diff -r $(OUT_TARGET)/outputs-base $(OUT_TARGET)/outputs-new && echo "outputs-compare: identical"

# The four library crates as crates.io would receive them: each packaged and its packaged copy
# built (`cargo package` resolves the crates' dependencies on one another through a local
# registry), and every crate's documentation without a warning (a broken or private link fails).
LIB_CRATES = -p tessla-syntax -p tessla-engine -p tessla-trace -p lineproto
# Cargo takes a registry's packages as immutable: it reuses an unpacked copy under
# $$CARGO_HOME/registry/src/-<hash>/ (the hash names the local registry's path, not the package's
# contents) and a build of it in the target folder, keyed by name and version. After a change to a
# crate's API, a copy left by an earlier run would fail the check for no fault of the tree. So the
# unpacked copies of our own crates go first (crates.io's sources, under index.crates.io-*, stay)
# and the packages are built in a target folder of their own, emptied each run.
CARGO_HOME_DIR = $${CARGO_HOME:-$$HOME/.cargo}
PACKAGE_TARGET = $(or $(CARGO_TARGET_DIR),target)/crates-package
crates-package:
	rm -rf $(PACKAGE_TARGET) $(foreach c,tessla-syntax tessla-engine tessla-trace lineproto,$(CARGO_HOME_DIR)/registry/src/-*/$(c)-[0-9]*)
	CARGO_TARGET_DIR=$(PACKAGE_TARGET) $(CARGO) package $(LIB_CRATES) --allow-dirty
	RUSTDOCFLAGS="-D warnings" $(CARGO) doc --no-deps --workspace
