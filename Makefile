# Two entry points for a fresh machine (see README): `make demo` and `make test`.
.PHONY: setup demo test test-all lint

setup:
	scripts/setup.sh

demo: setup
	scripts/demo.sh

test:
	scripts/setup.sh --tests
	.venv/bin/python -m pytest -q

test-all:
	scripts/setup.sh --tests
	.venv/bin/python -m pytest -q -m ""

lint: setup
	.venv/bin/ruff check nfr_drake tests benchmarks tutorials systems
