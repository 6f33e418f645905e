# keyfill: `make demo` and `make test` each create .venv, install keyfill with
# pinned dependencies (torch==2.13.0, the local CPU build; the onnx extra for export and
# the torch-free runtime) and run.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.keyfill-installed
# Blender's bpy wheel (for `make test-interop`) lives in its own venv: it pins its own numpy.
BLENDER_VENV := .venv-blender
BLENDER_STAMP := $(BLENDER_VENV)/.bpy-installed
OUT := out/demo

.PHONY: demo test test-slow test-interop fuzz clean

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -c constraints.txt -e '.[test,onnx]'
	@touch $(STAMP)

demo: $(STAMP)
	@mkdir -p $(OUT)
	$(BIN)/keyfill complete examples/mixamo_keys.usda -o $(OUT)/mixamo_cubic.usda --method cubic
	$(BIN)/keyfill convert $(OUT)/mixamo_cubic.usda $(OUT)/mixamo_cubic.bvh
	$(BIN)/keyfill complete examples/lamp/keys.usda -o $(OUT)/lamp_arnn.usda --method arnn
	$(BIN)/keyfill complete examples/lamp/keys.usda -o $(OUT)/lamp_cubic.usda --method cubic
	$(BIN)/keyfill plot examples/lamp/truth.usda $(OUT)/lamp_cubic.usda $(OUT)/lamp_arnn.usda --labels truth,cubic,arnn -o $(OUT)/lamp_arnn.png
	@echo "demo: completed examples/mixamo_keys.usda (cubic) and examples/lamp/keys.usda (ARNN, the model shipped in keyfill/learn/models/lamp-arnn); results in $(OUT)/ (mixamo_cubic.usda, mixamo_cubic.bvh, lamp_arnn.usda, lamp_cubic.usda, lamp_arnn.png)"

test: $(STAMP)
	$(BIN)/python -m pytest -q

test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -m slow

# Mutation fuzzing (tests/fuzzing.py): FUZZ_CASES inputs over 2 worker processes, each allowed
# FUZZ_MEM_MB of address space beyond its start-up size and FUZZ_TIMEOUT seconds per input.
FUZZ_CASES ?= 100000
FUZZ_MEM_MB ?= 2048
FUZZ_TIMEOUT ?= 20
fuzz: $(STAMP)
	$(BIN)/python tests/fuzzing.py --cases $(FUZZ_CASES) --jobs 2 --mem-mb $(FUZZ_MEM_MB) --timeout $(FUZZ_TIMEOUT)

$(BLENDER_STAMP):
	$(PYTHON) -m venv $(BLENDER_VENV)
	$(BLENDER_VENV)/bin/python -m pip install --quiet --disable-pip-version-check bpy==5.0.1
	@touch $(BLENDER_STAMP)

test-interop: $(STAMP) $(BLENDER_STAMP)
	$(BIN)/python -m pytest -q -m interop

clean:
	rm -rf $(VENV) $(BLENDER_VENV) out .pytest_cache
