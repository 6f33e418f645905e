# keyfill: `make demo` creates .venv and installs what the demo runs: keyfill's base install (pinned
# dependencies; every shipped model runs through onnxruntime, so no torch) and the human models' own
# distribution (models/bandai, CC BY-NC 4.0, editable: weights retrained into its folders are used at
# once). `make test` adds every extra (train: torch, pinned to 2.13.0, the local CPU build; sim: pybullet;
# dask; onnx: export; fbx: ufbx, for reading .fbx; test). `pip install .` alone installs none of the
# extras and no human model.
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.keyfill-installed
DEMO_STAMP := $(VENV)/.keyfill-demo-installed
# Blender's bpy wheel (for `make test-interop`) lives in its own venv: it pins its own numpy. pymotion, the
# other BVH reader the interop suite checks against, needs only numpy and shares it.
BLENDER_VENV := .venv-blender
BLENDER_STAMP := $(BLENDER_VENV)/.bpy-installed
OUT := out/demo

.PHONY: demo test test-slow test-interop blender-extension blender-pictures test-floors fuzz corpora gan-models gan-match-model gan-graphs transformer-model transformer-model-2 transformer-model-4 transformer-model-5 transformer-model-5q transformer-model-6 transformer-model-7 transformer-model-8 library pose-indexes gltf-validator clean

$(DEMO_STAMP): pyproject.toml constraints.txt models/bandai/pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -c constraints.txt -e .
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --no-deps -e ./models/bandai
	@touch $(DEMO_STAMP)

$(STAMP): $(DEMO_STAMP)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -c constraints.txt -e '.[test,onnx,train,sim,dask,fbx]'
	@touch $(STAMP)

demo: $(DEMO_STAMP)
	@mkdir -p $(OUT)
	$(BIN)/keyfill complete examples/mixamo_keys.usda -o $(OUT)/mixamo_cubic.usda --method cubic
	$(BIN)/keyfill convert $(OUT)/mixamo_cubic.usda $(OUT)/mixamo_cubic.bvh
	$(BIN)/keyfill complete examples/lamp/keys.usda -o $(OUT)/lamp_arnn.usda --method arnn
	$(BIN)/keyfill complete examples/lamp/keys.usda -o $(OUT)/lamp_cubic.usda --method cubic
	$(BIN)/keyfill plot examples/lamp/truth.usda $(OUT)/lamp_cubic.usda $(OUT)/lamp_arnn.usda --labels truth,cubic,arnn -o $(OUT)/lamp_arnn.png
	$(BIN)/keyfill complete examples/human/keys.usda -o $(OUT)/human_gan.usda --method gan --seed 1 --feet lock
	$(BIN)/keyfill complete examples/human/keys.usda -o $(OUT)/human_gan_raw.usda --method gan --seed 1 --feet free
	$(BIN)/keyfill complete examples/human/keys.usda -o $(OUT)/human_cubic.usda --method cubic
	$(BIN)/keyfill preview $(OUT)/human_cubic.usda $(OUT)/human_gan.usda --labels cubic,gan --view side -o $(OUT)/human.png
	$(BIN)/keyfill preview $(OUT)/human_gan_raw.usda $(OUT)/human_gan.usda --labels "gan raw,gan feet locked" --view side --frames 0:100 -o $(OUT)/human_feet.png
	$(BIN)/keyfill plot $(OUT)/human_gan_raw.usda $(OUT)/human_gan.usda --labels "gan raw,gan feet locked" --contacts --positions --joints Toes_L,Toes_R --channels y,z --frames 0:100 -o $(OUT)/human_feet_contacts.png
	$(BIN)/keyfill complete examples/human/keys_15.usda -o $(OUT)/human15_transformer.usda --method transformer
	$(BIN)/keyfill complete examples/human/keys_15.usda -o $(OUT)/human15_cubic.usda --method cubic
	$(BIN)/keyfill preview $(OUT)/human15_cubic.usda $(OUT)/human15_transformer.usda --labels cubic,transformer --view side -o $(OUT)/human15.png
	$(BIN)/keyfill complete examples/human/keys.usda -o $(OUT)/human_match.usda --method match
	$(BIN)/keyfill preview $(OUT)/human_cubic.usda $(OUT)/human_match.usda --labels cubic,match --view side --frames 68:137 --step 4 --trail Toes_L --size 1200x500 -o $(OUT)/human_match.png
	@echo "demo: completed examples/mixamo_keys.usda (cubic), examples/lamp/keys.usda (ARNN, the model shipped in keyfill/learn/models/lamp-arnn), examples/human/keys.usda (the shipped human gan model of models/bandai, CC BY-NC 4.0, with its feet locked and raw, and cubic) and examples/human/keys_15.usda (the shipped human transformer, CC BY-NC 4.0, and cubic) and examples/human/keys.usda again with --method match (the shipped motion library, CC BY-NC 4.0); results in $(OUT)/ (mixamo_cubic.usda, mixamo_cubic.bvh, lamp_arnn.usda, lamp_cubic.usda, lamp_arnn.png, human_gan.usda, human_gan_raw.usda, human_cubic.usda, human.png, human_feet.png (frames 0-99, raw against locked feet), human_feet_contacts.png (toe curves and foot contacts, frames 0-99), human15_transformer.usda, human15_cubic.usda, human15.png, human_match.usda and human_match.png: the shipped motion library's match against cubic over one 68-frame gap, the left toe's path: planted steps against a glide)"

test: $(STAMP)
	@command -v npm >/dev/null && $(MAKE) --no-print-directory gltf-validator \
	    || echo "make test: no npm (or no registry): tests/test_gltf.py skips the glTF validator"
	$(BIN)/ruff check keyfill tests benchmarks
	$(BIN)/python -m pytest -q

# The Khronos glTF validator (npm package, run with node by tests/interop/gltf_validate.js) for
# tests/test_gltf.py, which skips its check where this folder is absent.
GLTF_VALIDATOR := .venv-gltf-validator
gltf-validator: $(GLTF_VALIDATOR)/node_modules/gltf-validator/package.json

$(GLTF_VALIDATOR)/node_modules/gltf-validator/package.json:
	npm install --prefix $(GLTF_VALIDATOR) --no-save --no-audit --no-fund --silent gltf-validator@2.0.0-dev.3.10

# The declared floors: a venv of its own with every base dependency at the lowest version pyproject.toml
# allows (each `>=X` installed as `==X`) and the test extra's pytest and hypothesis at theirs, no torch; keyfill
# goes on top as a wheel without dependencies (so its package data is checked too), then the CLI smoke tests
# (marker floors, tests/test_floors_smoke.py) run on it. Blender's Python pins numpy 1.26.4, the floor's series.
FLOORS_VENV := .venv-floors
FLOORS_STAMP := $(FLOORS_VENV)/.floors-installed
FLOOR_PINS = $(PYTHON) -c "import re, tomllib; p = tomllib.load(open('pyproject.toml', 'rb'))['project']; \
    tools = [r for r in p['optional-dependencies']['test'] if re.match('(pytest|hypothesis)>=', r)]; \
    print('\n'.join(r.replace('>=', '==') for r in p['dependencies'] + tools))"

$(FLOORS_STAMP): pyproject.toml
	rm -rf $(FLOORS_VENV)
	$(PYTHON) -m venv $(FLOORS_VENV)
	$(FLOOR_PINS) > $(FLOORS_VENV)/floors.txt
	$(FLOORS_VENV)/bin/python -m pip install --quiet --disable-pip-version-check -r $(FLOORS_VENV)/floors.txt
	@touch $(FLOORS_STAMP)

test-floors: $(FLOORS_STAMP)
	$(FLOORS_VENV)/bin/python -m pip install --quiet --disable-pip-version-check --no-deps --force-reinstall .
	$(FLOORS_VENV)/bin/python -m pip freeze --exclude keyfill | tr '\n' ' '; echo
	$(FLOORS_VENV)/bin/pytest -q -p no:cacheprovider -m floors tests/test_floors_smoke.py

test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -m slow

# Mutation fuzzing (tests/fuzzing.py): FUZZ_CASES inputs over 2 worker processes, each allowed
# FUZZ_MEM_MB of address space beyond its start-up size and FUZZ_TIMEOUT seconds per input.
FUZZ_CASES ?= 100000
FUZZ_MEM_MB ?= 2048
FUZZ_TIMEOUT ?= 20
fuzz: $(STAMP)
	$(BIN)/python tests/fuzzing.py --cases $(FUZZ_CASES) --jobs 2 --mem-mb $(FUZZ_MEM_MB) --timeout $(FUZZ_TIMEOUT)

# The human models of the distribution models/bandai (CC BY-NC 4.0; MODELS: where to train them; a
# retrained model replaces a shipped one by copying its folder into models/bandai/keyfill_models_bandai/).
# The gan models of docs/gan.md and docs/benchmarks.md, trained on Bandai-Namco dataset-2 and dataset-1
# (unpacked from ../shared/data into data/bandai2 and data/bandai1 on first use) with three styles held
# out for the figures: `normal` (both datasets), and dataset-1's `sad` and `feminine`. `bandai2-gan`
# (Motion DNA, gaps up to 600 frames) by the third recipe (benchmarks/gan_recipe3.json, docs/gan.md
# "The third recipe"): a generator correcting the cubic spline, no path predictor. `bandai2-gan-partial`
# (partial keys too, gaps up to 318) by the second (benchmarks/gan_recipe2.json): partial keys give no
# rotations to interpolate, so its root path comes from the global path predictor (the first recipe's, on
# dataset-2 alone: 9 minutes; on both datasets its whole-clip batches grow to 1,024 frames and an epoch
# takes 7x as long). An interrupted run continues from its checkpoints; a finished stage is not
# retrained. Torch thread counts are part of the recipe (results are bitwise reproducible for a given count).
BANDAI2 := data/bandai2/bandai_namco_motiondataset2/data
BANDAI1 := data/bandai1/Bandai-Namco-Research-Motiondataset-1/data
MODELS := data/models
GAN_TRAIN = $(BIN)/keyfill train gan $(BANDAI2) $(BANDAI1) --exclude '*_normal_*' --exclude 'dataset-1_*_sad_*' \
    --exclude 'dataset-1_*_feminine_*' --seed 0
resume_if = $(if $(wildcard $(1).checkpoint.pt),--resume)

$(BANDAI2): | $(STAMP)
	$(BIN)/python -c "from keyfill.learn.corpus import locate; print(locate('bandai2'))"

$(BANDAI1): | $(STAMP)
	$(BIN)/python -c "from keyfill.learn.corpus import locate; print(locate('bandai1'))"

# The corpora of the README's training tour (and of the models and the library below): Bandai-Namco dataset-1
# (174 clips, 40 MB) and dataset-2 (2,501 clips, about 430 MB), unpacked once from ../shared/data/corpora
# (KEYFILL_SHARED_DATA: another folder of the archives) into the git-ignored data/. A re-run does nothing.
corpora: | $(BANDAI1) $(BANDAI2)
	@echo "corpora: dataset-1 in $(BANDAI1), dataset-2 in $(BANDAI2)"

$(MODELS)/bandai2-gan-path/weights.safetensors: | $(BANDAI2)
	@mkdir -p $(dir $(@D))
	$(BIN)/keyfill train gan $(BANDAI2) --exclude '*_normal_*' --seed 0 -o $(MODELS)/bandai2-gan-path --stage path \
	    --threads 2 $(call resume_if,$(MODELS)/bandai2-gan-path)

$(MODELS)/bandai2-gan/weights.safetensors: | $(BANDAI2) $(BANDAI1)
	@mkdir -p $(dir $(@D))
	$(GAN_TRAIN) --config benchmarks/gan_recipe3.json -o $(MODELS)/bandai2-gan --stage generator \
	    --dna --threads 1 $(call resume_if,$(MODELS)/bandai2-gan)

$(MODELS)/bandai2-gan-partial/weights.safetensors: $(MODELS)/bandai2-gan-path/weights.safetensors | $(BANDAI1)
	@mkdir -p $(dir $(@D))
	$(GAN_TRAIN) --config benchmarks/gan_recipe2.json -o $(MODELS)/bandai2-gan-partial --stage generator \
	    --path-model $(MODELS)/bandai2-gan-path --dna --partial-keys --threads 1 \
	    $(call resume_if,$(MODELS)/bandai2-gan-partial)

# Issue 45's gan on a matched base (docs/gan.md "On a matched base"): the matched set of the gan's corpus
# (benchmarks/gan_matched_set.py: each fold by style matched from a library of the other, 6 in-clip windows per
# clip, 150 s), then the generator of benchmarks/gan_recipe6_match_seen.json (the third recipe correcting the
# match instead of the spline and reading it, in-clip windows only, distances as losses) on one thread: 40 epochs,
# about 40 minutes. Interrupted, it continues from its checkpoint.
GAN_MATCHED := data/starts/gan12.npz

$(GAN_MATCHED): benchmarks/gan_recipe6_match_seen.json | $(BANDAI2) $(BANDAI1)
	$(BIN)/python benchmarks/gan_matched_set.py --config benchmarks/gan_recipe6_match_seen.json -o $@

$(MODELS)/bandai2-gan-match/weights.safetensors: $(GAN_MATCHED)
	$(GAN_TRAIN) --config benchmarks/gan_recipe6_match_seen.json -o $(MODELS)/bandai2-gan-match --stage generator \
	    --dna --threads 1 $(call resume_if,$(MODELS)/bandai2-gan-match)

gan-match-model: $(MODELS)/bandai2-gan-match/weights.safetensors

# `make -j2 gan-models` trains the two generators side by side, one core each
gan-models: $(MODELS)/bandai2-gan/weights.safetensors $(MODELS)/bandai2-gan-partial/weights.safetensors

# Once the gan models are copied into the distribution, `make gan-graphs` exports each one's ONNX graph
# (model.onnx beside its weights; docs/onnx.md): `keyfill complete --method gan` then runs through
# onnxruntime without torch. Only noise-free models (the second recipe) export. A graph is remade when its
# model's weights or config change.
SHIPPED := models/bandai/keyfill_models_bandai
$(SHIPPED)/%/model.onnx: $(SHIPPED)/%/weights.safetensors $(SHIPPED)/%/config.json | $(STAMP)
	$(BIN)/keyfill export $(SHIPPED)/$*

gan-graphs: $(SHIPPED)/bandai2-gan/model.onnx $(SHIPPED)/bandai2-gan-partial/model.onnx

# The shipped motion library of `--method match` (docs/match.md; its MODEL_CARD.md): every third clip of
# dataset-2 and dataset-1 without the held-out styles (normal; dataset-1's sad and feminine), half precision,
# 31.8 MiB; a re-run reads no clip (their SHA-256 are in its library.json). Without --every 3 --precision half
# the same command builds the full library (2,168 clips, 184 MiB). `make pose-indexes` writes each shipped
# human model's pose index (the guard's) from the clips it was trained on (keyfill train writes it for new models).
LIBRARY_CLIPS := --exclude '*_normal_*' --exclude 'dataset-1_*_sad_*' --exclude 'dataset-1_*_feminine_*'
library: | $(BANDAI2) $(BANDAI1)
	$(BIN)/keyfill library build $(BANDAI2) $(BANDAI1) $(LIBRARY_CLIPS) --every 3 --precision half \
	    -o $(SHIPPED)/bandai2-library

pose-indexes: | $(BANDAI2) $(BANDAI1)
	$(BIN)/keyfill library index $(SHIPPED)/bandai2-transformer $(BANDAI2) --exclude '*_normal_*'
	$(BIN)/keyfill library index $(SHIPPED)/bandai2-gan $(BANDAI2) $(BANDAI1) $(LIBRARY_CLIPS)
	$(BIN)/keyfill library index $(SHIPPED)/bandai2-gan-partial $(BANDAI2) $(BANDAI1) $(LIBRARY_CLIPS)

# The shipped transformer (docs/transformer.md), in two steps, one thread each: the base model, the
# benchmark's config with the SLERP pre-fill (about 3 hours of one core of the project's VM, 2.9 h
# measured), then 24 epochs from it with the velocity pre-fill and a falling rate (66 minutes measured).
# Interrupted, each continues from its checkpoint.
TRANSFORMER_TRAIN = $(BIN)/keyfill train transformer $(BANDAI2) --exclude '*_normal_*' --seed 0 --threads 1

$(MODELS)/base/bandai2-transformer/weights.safetensors: | $(BANDAI2)
	@mkdir -p $(dir $(@D))
	$(TRANSFORMER_TRAIN) -o $(MODELS)/base/bandai2-transformer --config benchmarks/bench_transformer_bandai2.json \
	    $(call resume_if,$(MODELS)/base/bandai2-transformer)

$(MODELS)/bandai2-transformer/weights.safetensors: $(MODELS)/base/bandai2-transformer/weights.safetensors
	@mkdir -p $(dir $(@D))
	$(TRANSFORMER_TRAIN) -o $(MODELS)/bandai2-transformer --init $(MODELS)/base/bandai2-transformer \
	    --config benchmarks/bench_transformer_bandai2_tune.json $(call resume_if,$(MODELS)/bandai2-transformer)

transformer-model: $(MODELS)/bandai2-transformer/weights.safetensors

# Issue 30's retraining for unseen styles (docs/transformer.md "Retraining for unseen styles"; trained and
# scored there, not shipped):
# Bandai-Namco dataset-2 and dataset-1 together, mirrored left-right, with two held-out styles never used
# to choose settings, `normal` (both datasets) and dataset-2's `elderly` (and dataset-1's `old`, the same
# idea, so that elderly stays unseen), and dataset-1's `sad` and `feminine` left out too, which the gan
# holds out for its figures, so that both methods' feet benchmark sees them unseen. Two steps, one thread
# each, as transformer-model: the base model with the benchmark's config (60 epochs of 6,528 windows, 1.71 h
# measured), then 24 epochs from it with
# benchmarks/transformer_recipe2.json: the shipped model's fine-tune settings (the foot-sliding and excess-jerk
# terms cost accuracy on the validation clips and are off; docs/transformer.md). Interrupted, each continues
# from its checkpoint.
TRANSFORMER2_TRAIN = $(BIN)/keyfill train transformer $(BANDAI2) $(BANDAI1) --exclude '*_normal_*' \
    --exclude '*_elderly_*' --exclude 'dataset-1_*_old_*' --exclude 'dataset-1_*_sad_*' \
    --exclude 'dataset-1_*_feminine_*' --seed 0 --threads 1

$(MODELS)/base/bandai-transformer-2/weights.safetensors: | $(BANDAI2) $(BANDAI1)
	@mkdir -p $(dir $(@D))
	$(TRANSFORMER2_TRAIN) -o $(MODELS)/base/bandai-transformer-2 --config benchmarks/bench_transformer_bandai2.json \
	    $(call resume_if,$(MODELS)/base/bandai-transformer-2)

$(MODELS)/bandai-transformer-2/weights.safetensors: $(MODELS)/base/bandai-transformer-2/weights.safetensors
	@mkdir -p $(dir $(@D))
	$(TRANSFORMER2_TRAIN) -o $(MODELS)/bandai-transformer-2 --init $(MODELS)/base/bandai-transformer-2 \
	    --config benchmarks/transformer_recipe2.json $(call resume_if,$(MODELS)/bandai-transformer-2)

transformer-model-2: $(MODELS)/bandai-transformer-2/weights.safetensors

# Issue 30's fourth recipe (docs/transformer.md "A longer base step"): the same corpus and held-out styles as
# transformer-model-2, with the posture augmentation (0.35 rad) in both steps and a base step of 180 epochs
# instead of 60 (2.2 h on two threads of the project's VM; one thread would take about 5 h, over the issue's
# 2.5 h a step), then 24 epochs of benchmarks/transformer_recipe3_posture.json (18 minutes). Two threads each:
# it needs the whole machine. Interrupted, each continues from its checkpoint.
TRANSFORMER4_TRAIN = $(subst --threads 1,--threads 2,$(TRANSFORMER2_TRAIN))

$(MODELS)/base/bandai-transformer-4/weights.safetensors: | $(BANDAI2) $(BANDAI1)
	@mkdir -p $(dir $(@D))
	$(TRANSFORMER4_TRAIN) -o $(MODELS)/base/bandai-transformer-4 --config benchmarks/transformer_recipe4_base.json \
	    $(call resume_if,$(MODELS)/base/bandai-transformer-4)

$(MODELS)/bandai-transformer-4/weights.safetensors: $(MODELS)/base/bandai-transformer-4/weights.safetensors
	@mkdir -p $(dir $(@D))
	$(TRANSFORMER4_TRAIN) -o $(MODELS)/bandai-transformer-4 --init $(MODELS)/base/bandai-transformer-4 \
	    --config benchmarks/transformer_recipe3_posture.json $(call resume_if,$(MODELS)/bandai-transformer-4)

transformer-model-4: $(MODELS)/bandai-transformer-4/weights.safetensors

# Issue 46's matched starts (docs/transformer.md "Started from a matched in-between"; trained and scored there,
# not shipped): the start set (benchmarks/transformer_starts.py: dataset-2 without `normal` in two folds by style,
# each fold's windows matched from a library of the other's; about 4 minutes on two cores), then the shipped
# transformer fine-tuned on it, 12 epochs, one thread (about 25 minutes), with half of the batches
# (transformer-model-5, benchmarks/transformer_recipe5_starts.json) or a quarter (transformer-model-5q,
# transformer_recipe5_starts25.json) drawn from the start set. Interrupted, each continues from its checkpoint.
STARTS := data/starts/bandai2.npz
# $(call tune_shipped,TRAIN COMMAND,MODEL,CONFIG): fine-tune the shipped transformer into $(MODELS)/MODEL
tune_shipped = $(1) -o $(MODELS)/$(2) --init $(SHIPPED)/bandai2-transformer --config benchmarks/$(3) \
    $(call resume_if,$(MODELS)/$(2))

$(STARTS): | $(BANDAI2)
	$(BIN)/python benchmarks/transformer_starts.py -o $@

$(MODELS)/bandai2-transformer-starts/weights.safetensors: $(STARTS)
	@mkdir -p $(dir $(@D))
	$(call tune_shipped,$(TRANSFORMER_TRAIN),bandai2-transformer-starts,transformer_recipe5_starts.json)

$(MODELS)/bandai2-transformer-starts25/weights.safetensors: $(STARTS)
	@mkdir -p $(dir $(@D))
	$(call tune_shipped,$(TRANSFORMER_TRAIN),bandai2-transformer-starts25,transformer_recipe5_starts25.json)

transformer-model-5: $(MODELS)/bandai2-transformer-starts/weights.safetensors
transformer-model-5q: $(MODELS)/bandai2-transformer-starts25/weights.safetensors

# The same with dataset-1 (without its held-out normal, sad and feminine) in the corpus and in the start set's
# folds (transformer_starts.py --dataset-1): 8 epochs of benchmarks/transformer_recipe6_starts12.json
# (transformer-model-6); gently, a quarter of the batches at half the rate (transformer-model-7,
# transformer_recipe7_starts12_gentle.json); gently with the excess-jerk term in training (smooth_weight
# 0.00025, issue 30's trial weight), two threads, 13 minutes (transformer-model-8,
# transformer_recipe8_starts12_smooth.json).
STARTS12 := data/starts/bandai12.npz
TRANSFORMER12_TRAIN = $(BIN)/keyfill train transformer $(BANDAI2) $(BANDAI1) --exclude '*_normal_*' \
    --exclude 'dataset-1_*_sad_*' --exclude 'dataset-1_*_feminine_*' --seed 0 --threads 1
TRANSFORMER12_TRAIN_2 = $(subst --threads 1,--threads 2,$(TRANSFORMER12_TRAIN))

$(STARTS12): | $(BANDAI2) $(BANDAI1)
	$(BIN)/python benchmarks/transformer_starts.py --dataset-1 -o $@

$(MODELS)/bandai12-transformer-starts/weights.safetensors: $(STARTS12)
	@mkdir -p $(dir $(@D))
	$(call tune_shipped,$(TRANSFORMER12_TRAIN),bandai12-transformer-starts,transformer_recipe6_starts12.json)

$(MODELS)/bandai12-transformer-gentle/weights.safetensors: $(STARTS12)
	@mkdir -p $(dir $(@D))
	$(call tune_shipped,$(TRANSFORMER12_TRAIN),bandai12-transformer-gentle,transformer_recipe7_starts12_gentle.json)

$(MODELS)/bandai12-transformer-smooth/weights.safetensors: $(STARTS12)
	@mkdir -p $(dir $(@D))
	$(call tune_shipped,$(TRANSFORMER12_TRAIN_2),bandai12-transformer-smooth,transformer_recipe8_starts12_smooth.json)

transformer-model-6: $(MODELS)/bandai12-transformer-starts/weights.safetensors
transformer-model-7: $(MODELS)/bandai12-transformer-gentle/weights.safetensors
transformer-model-8: $(MODELS)/bandai12-transformer-smooth/weights.safetensors

$(BLENDER_STAMP): Makefile
	$(PYTHON) -m venv $(BLENDER_VENV)
	$(BLENDER_VENV)/bin/python -m pip install --quiet --disable-pip-version-check bpy==5.0.1 upc-pymotion==0.3.4
	@touch $(BLENDER_STAMP)

# keyfill (the base install, no torch) and the human models in Blender's venv, for the Blender extension
# (blender/keyfill_blender, docs/blender.md): bpy pins numpy 1.26.4, keyfill's floor series, so the
# project's constraints are used with that numpy.
BLENDER_KEYFILL_STAMP := $(BLENDER_VENV)/.keyfill-installed
$(BLENDER_KEYFILL_STAMP): $(BLENDER_STAMP) pyproject.toml constraints.txt models/bandai/pyproject.toml
	grep -v '^numpy==' constraints.txt > $(BLENDER_VENV)/constraints.txt
	echo 'numpy==1.26.4' >> $(BLENDER_VENV)/constraints.txt
	$(BLENDER_VENV)/bin/python -m pip install --quiet --disable-pip-version-check -c $(BLENDER_VENV)/constraints.txt -e .
	$(BLENDER_VENV)/bin/python -m pip install --quiet --disable-pip-version-check --no-deps -e ./models/bandai
	@touch $(BLENDER_KEYFILL_STAMP)

# The Blender extension's zip (what Blender 4.2+ installs: Preferences > Get Extensions > Install from Disk, or
# `blender --command extension install-file -r user_default out/blender/keyfill-VERSION.zip`): the files of
# blender/keyfill_blender at the zip's top, blender_manifest.toml among them.
BLENDER_EXT_VERSION := $(shell sed -n 's/^version = "\(.*\)"/\1/p' blender/keyfill_blender/blender_manifest.toml)
BLENDER_ZIP := out/blender/keyfill-$(BLENDER_EXT_VERSION).zip
blender-extension: $(BLENDER_ZIP)

$(BLENDER_ZIP): $(wildcard blender/keyfill_blender/*.py) blender/keyfill_blender/blender_manifest.toml
	@mkdir -p $(@D)
	$(PYTHON) -c "import sys, zipfile, pathlib; src = pathlib.Path('blender/keyfill_blender'); \
	    z = zipfile.ZipFile(sys.argv[1], 'w', zipfile.ZIP_DEFLATED); \
	    [z.write(p, p.relative_to(src).as_posix()) for p in sorted(src.rglob('*')) if p.is_file() and '__pycache__' not in p.parts]; \
	    z.close()" $@

test-interop: $(STAMP) $(BLENDER_STAMP) $(BLENDER_KEYFILL_STAMP) $(BLENDER_ZIP)
	$(BIN)/python -m pytest -q -m interop

# The pictures of docs/blender.md: both operators run in bpy and rendered headless (Workbench through EGL).
blender-pictures: $(BLENDER_STAMP) $(BLENDER_KEYFILL_STAMP)
	$(BLENDER_VENV)/bin/python blender/render_pictures.py

clean:
	rm -rf $(VENV) $(BLENDER_VENV) $(FLOORS_VENV) $(GLTF_VALIDATOR) out .pytest_cache
