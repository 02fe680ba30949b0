# splatd — build, test, bench, run, install.
#
#   make            build bin/splatd, bin/splat, bin/splat-view, libsplatclient.{a,so}
#   make test       unit, rendering, protocol and end-to-end tests, then the same under ASan+UBSan
#                   (T='test_lod:test_octree* test_params' runs those programs and tests only)
#   make asan       only the AddressSanitizer + UBSan test run
#   make bench      measured numbers (see README.md)
#   make run        start the daemon on a bundled scan and render an orbit into ./out/
#                   (RUN_ARGS=--force renders frames that exist again)
#   make fuzz       libFuzzer targets for the protocol and every parser (FUZZ_SECONDS=60 each)
#   make fuzz-smoke builds every fuzz target and runs each for FUZZ_SMOKE_SECONDS (4; CI)
#   make install    PREFIX=/usr/local DESTDIR= (runs ldconfig when installing as root)
#
# Every dependency comes through pkg-config; when a check fails, deploy/deps.sh installs the
# Debian packages (so a fresh machine needs only make, gcc and git).

CC      ?= cc
PREFIX  ?= /usr/local
BUILD   ?= build
.DEFAULT_GOAL := all

# ---- dependencies: deploy/deps.sh lists each pkg-config module (or header/driver file) and the
# Debian package that provides it. When one is missing, deps.sh installs the packages; if one is
# still missing afterwards, the build stops naming it and its package (one failed module would
# otherwise empty a whole `pkg-config --libs` line and surface later as an unrelated link error).
ifeq ($(filter clean,$(MAKECMDGOALS)),)
DEPS_MISSING := $(shell CC=$(CC) sh deploy/deps.sh --check)
ifneq ($(DEPS_MISSING),)
$(info splatd: missing $(DEPS_MISSING); running deploy/deps.sh)
DEPS_RC := $(shell CC=$(CC) sh deploy/deps.sh 1>&2; echo $$?)
DEPS_MISSING := $(shell CC=$(CC) sh deploy/deps.sh --check | tr '\n' ';')
ifneq ($(DEPS_MISSING),)
$(error still missing after deploy/deps.sh (exit $(DEPS_RC)): $(DEPS_MISSING) install them and retry)
endif
endif
endif

# FLANN's and OpenEXR's .pc files drag in C++ libraries, HDF5 and MPI; the C APIs need only these.
FLANN_LIBS := -lflann
EXR_CFLAGS := -I/usr/include/OpenEXR
EXR_LIBS   := -lOpenEXRCore

PKG_CFLAGS := $(shell pkg-config --cflags egl opengl osmesa libturbojpeg libpng liblz4 libssl libcrypto cmocka expat 2>/dev/null)
# Link lines per binary: each gets only the libraries it uses.
#   CLIENT_LIBS  libsplatclient and the `splat` command: TLS, HMAC, frame decoding (LZ4, JPEG)
#   SERVER_LIBS  splatd and the tools built on libsplatd: GL back ends, kNN, encoders, expat
#                (the E57 reader's XML section)
#   TEST_LIBS    the test and bench programs, which link both libraries
CLIENT_LIBS := $(shell pkg-config --libs libssl libcrypto liblz4 libturbojpeg 2>/dev/null) -lm
SERVER_LIBS := $(shell pkg-config --libs egl opengl osmesa libturbojpeg libpng liblz4 libssl libcrypto libxxhash liblzf expat 2>/dev/null) \
               $(FLANN_LIBS) $(EXR_LIBS) -lpthread -lm
TEST_LIBS   := $(SERVER_LIBS) $(shell pkg-config --libs cmocka 2>/dev/null)
#   VIEW_LIBS    splat-view, the SDL2 window of `splat view` (a binary of its own, so that
#                `splat` and libsplatclient never need SDL2 or X11)
SDL_CFLAGS  := $(shell pkg-config --cflags sdl2 2>/dev/null)
VIEW_LIBS   := $(CLIENT_LIBS) $(shell pkg-config --libs sdl2 2>/dev/null) -lpthread

WARN    := -Wall -Wextra -Werror -Wshadow -Wstrict-prototypes -Wmissing-prototypes -Wno-unused-parameter
CFLAGS  ?= -O2 -g
BASE_CFLAGS = -std=c11 -D_GNU_SOURCE -fPIC $(WARN) $(CFLAGS) $(PKG_CFLAGS) $(EXR_CFLAGS) -MMD -MP

# ---- include paths per directory: the boundaries the build enforces ----
# Data flows one way: file -> cloud (io) -> prepared cloud (prep) -> GPU (render, pipelines)
# -> frame (enc) -> socket (net, daemon). A folder sees its own headers, those of the folders
# before it, util and protocol; nothing later. The client sees protocol and itself, never the
# server; protocol sees only itself. Tests and tools see everything.
SERVER_DIRS    := util io prep render pipelines enc net daemon cmd
DEPS_util      := util
DEPS_io        := util io
DEPS_prep      := util io prep
DEPS_render    := util io prep render
DEPS_pipelines := util io prep render pipelines
DEPS_enc       := util io prep render enc
DEPS_net       := util io prep render net
DEPS_daemon    := $(SERVER_DIRS)
DEPS_cmd       := $(SERVER_DIRS)
$(foreach d,$(SERVER_DIRS),$(eval INC_server/$(d) := -Iprotocol $(addprefix -Iserver/,$(DEPS_$(d)))))
INC_render_gen := -I$(BUILD)/gen
INC_server/render += $(INC_render_gen)
INC_server/daemon += $(INC_render_gen)
INC_protocol   := -Iprotocol
INC_client     := -Iprotocol -Iclient
INC_ALL        := -Iprotocol $(addprefix -Iserver/,$(SERVER_DIRS)) -Iclient -Itests -Itests/common $(INC_render_gen) -Iserver/mpi
# server/mpi (splatd-mpi, `splatd --mpi`) sits on top of everything, like cmd; nothing but the
# tests sees it.
INC_server/mpi := -Iprotocol $(addprefix -Iserver/,$(SERVER_DIRS) mpi)
# inc_of SRC: the include flags of the directory SRC is in (tests/, tools/: all of them).
inc_of = $(or $(INC_$(patsubst %/,%,$(dir $(1)))),$(INC_ALL))

PROTO_SRC  := $(wildcard protocol/*.c)
SERVER_SRC := $(filter-out server/cmd/main.c server/mpi/%,$(wildcard server/*/*.c))
CLIENT_LIB_SRC := $(filter-out client/splat_main.c client/splat_view.c,$(wildcard client/*.c))
SHADERS    := $(sort $(wildcard shaders/*.glsl))
WEB        := $(sort $(wildcard web/*.html web/*.js web/*.css))
TEST_SRC   := $(wildcard tests/test_*.c)
TEST_COMMON_SRC := $(wildcard tests/common/*.c)
TOOL_SRC   := $(wildcard tests/tools/*.c)
BENCH_SRC  := $(wildcard tests/bench/*.c)

obj = $(patsubst %.c,$(1)/obj/%.o,$(2))

# Full builds (no goal, or all/test/asan/bench/run/install) are strict: any error stops them.
# A single-target build (make build/tests/test_x) builds the libraries tolerantly through
# tools/dev_archive.sh, so one half-edited file does not block work on the others.
ifeq ($(strip $(MAKECMDGOALS)),)
STRICT ?= 1
else ifneq ($(filter all test asan bench run install,$(MAKECMDGOALS)),)
STRICT ?= 1
else
STRICT ?= 0
endif
.PHONY: FORCE
FORCE:

# ---- one build directory per flavour: normal ($(BUILD)) and ASan+UBSan ($(BUILD)/asan) ----
define FLAVOUR
$(1)/obj/%.o: %.c $(BUILD)/gen/shaders_gen.h
	@mkdir -p $$(dir $$@)
	$$(CC) $$(BASE_CFLAGS) $$(call inc_of,$$<) $(2) -c $$< -o $$@

$(1)/obj/gen/shaders_gen.o: $(BUILD)/gen/shaders_gen.c
	@mkdir -p $$(dir $$@)
	$$(CC) $$(BASE_CFLAGS) $(INC_render_gen) $(2) -c $$< -o $$@

# Only the daemon's start-up includes the page table (a page edit rebuilds that and page_gen.o).
$(1)/obj/server/daemon/daemon.o: $(BUILD)/gen/page_gen.h

$(1)/obj/gen/page_gen.o: $(BUILD)/gen/page_gen.c
	@mkdir -p $$(dir $$@)
	$$(CC) $$(BASE_CFLAGS) $(INC_render_gen) $(2) -c $$< -o $$@

ifeq ($(STRICT),1)
$(1)/libsplatd.a: $(call obj,$(1),$(SERVER_SRC)) $(1)/obj/gen/shaders_gen.o $(1)/obj/gen/page_gen.o
	@rm -f $$@; ar rcs $$@ $$^

$(1)/libsplatproto.a: $(call obj,$(1),$(PROTO_SRC))
	@rm -f $$@; ar rcs $$@ $$^

$(1)/libsplatclient.a: $(call obj,$(1),$(CLIENT_LIB_SRC) $(PROTO_SRC))
	@rm -f $$@; ar rcs $$@ $$^

$(1)/libtestcommon.a: $(call obj,$(1),$(TEST_COMMON_SRC))
	@rm -f $$@; ar rcs $$@ $$^
else
$(1)/libsplatd.a: FORCE $(BUILD)/gen/shaders_gen.c $(BUILD)/gen/page_gen.c
	@sh tools/dev_archive.sh "$$(CC) $$(BASE_CFLAGS) $$(INC_ALL) $(2)" $(1) $$@ $(SERVER_SRC) $(BUILD)/gen/shaders_gen.c $(BUILD)/gen/page_gen.c

$(1)/libsplatproto.a: FORCE
	@sh tools/dev_archive.sh "$$(CC) $$(BASE_CFLAGS) $$(INC_ALL) $(2)" $(1) $$@ $(PROTO_SRC)

$(1)/libsplatclient.a: FORCE
	@sh tools/dev_archive.sh "$$(CC) $$(BASE_CFLAGS) $$(INC_ALL) $(2)" $(1) $$@ $(CLIENT_LIB_SRC) $(PROTO_SRC)

$(1)/libtestcommon.a: FORCE
	@sh tools/dev_archive.sh "$$(CC) $$(BASE_CFLAGS) $$(INC_ALL) $(2)" $(1) $$@ $(TEST_COMMON_SRC)
endif

$(1)/bin/splatd: $(1)/obj/server/cmd/main.o $(1)/libsplatd.a $(1)/libsplatproto.a
	@mkdir -p $$(dir $$@)
	$$(CC) $(2) -o $$@ $$^ $$(SERVER_LIBS)

$(1)/bin/splat: $(1)/obj/client/splat_main.o $(1)/libsplatclient.a
	@mkdir -p $$(dir $$@)
	$$(CC) $(2) -o $$@ $$^ $$(CLIENT_LIBS)

$(1)/obj/client/splat_view.o: BASE_CFLAGS += $(SDL_CFLAGS)

$(1)/bin/splat-view: $(1)/obj/client/splat_view.o $(1)/libsplatclient.a
	@mkdir -p $$(dir $$@)
	$$(CC) $(2) -o $$@ $$^ $$(VIEW_LIBS)

$(1)/tests/%: $(1)/obj/tests/%.o $(1)/libtestcommon.a $(1)/libsplatd.a $(1)/libsplatclient.a
	@mkdir -p $$(dir $$@)
	$$(CC) $(2) -o $$@ $$^ $$(TEST_LIBS)

$(1)/tools/%: $(1)/obj/tests/tools/%.o $(1)/libsplatd.a $(1)/libsplatproto.a
	@mkdir -p $$(dir $$@)
	$$(CC) $(2) -o $$@ $$^ $$(SERVER_LIBS)

$(1)/bench/%: $(1)/obj/tests/bench/%.o $(1)/libtestcommon.a $(1)/libsplatd.a $(1)/libsplatclient.a
	@mkdir -p $$(dir $$@)
	$$(CC) $(2) -o $$@ $$^ $$(TEST_LIBS)
endef

# ---- splatd-mpi: sort-last rendering over MPI (server/mpi/), built only where mpicc is (Open
# MPI: deploy/deps.sh installs it for the tests); splatd itself never links MPI.
MPICC := $(shell command -v mpicc 2>/dev/null)
ifneq ($(MPICC),)
MPI_SRC    := $(wildcard server/mpi/*.c)
MPI_CFLAGS := $(shell mpicc --showme:compile 2>/dev/null)
MPI_LIBS   := $(shell mpicc --showme:link 2>/dev/null)
define MPI_FLAVOUR
$(1)/obj/server/mpi/%.o: BASE_CFLAGS += $(MPI_CFLAGS)
$(1)/bin/splatd-mpi: $(call obj,$(1),$(MPI_SRC)) $(1)/libsplatd.a $(1)/libsplatproto.a
	@mkdir -p $$(dir $$@)
	$$(CC) $(2) -o $$@ $$^ $$(SERVER_LIBS) $(MPI_LIBS)
endef
MPI_BIN      := $(BUILD)/bin/splatd-mpi
MPI_ASAN_BIN := $(BUILD)/asan/bin/splatd-mpi
endif

ASAN_FLAGS := -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined
$(eval $(call FLAVOUR,$(BUILD),))
$(eval $(call FLAVOUR,$(BUILD)/asan,$(ASAN_FLAGS)))
ifneq ($(MPICC),)
$(eval $(call MPI_FLAVOUR,$(BUILD),))
$(eval $(call MPI_FLAVOUR,$(BUILD)/asan,$(ASAN_FLAGS)))
endif
# test_mpi also tests the parts of server/mpi that need no MPI (the parts' order, "over", the
# ranks' records); test_fuzz_regress replays the records' fuzz target
MPI_PLAIN_SRC := server/mpi/boxorder.c server/mpi/over.c server/mpi/mr_msg.c
$(BUILD)/tests/test_mpi: $(call obj,$(BUILD),$(MPI_PLAIN_SRC))
$(BUILD)/asan/tests/test_mpi: $(call obj,$(BUILD)/asan,$(MPI_PLAIN_SRC))
$(BUILD)/tests/test_fuzz_regress: $(call obj,$(BUILD),server/mpi/mr_msg.c)
$(BUILD)/asan/tests/test_fuzz_regress: $(call obj,$(BUILD)/asan,server/mpi/mr_msg.c)

TESTS       := $(patsubst tests/%.c,$(BUILD)/tests/%,$(TEST_SRC))
ASAN_TESTS  := $(patsubst tests/%.c,$(BUILD)/asan/tests/%,$(TEST_SRC))
TOOLS       := $(patsubst tests/tools/%.c,$(BUILD)/tools/%,$(TOOL_SRC))
ASAN_TOOLS  := $(patsubst tests/tools/%.c,$(BUILD)/asan/tools/%,$(TOOL_SRC))
BENCHES     := $(patsubst tests/bench/%.c,$(BUILD)/bench/%,$(BENCH_SRC))

# Shaders are compiled into the daemon from a generated C file.
$(BUILD)/embed_shaders: tools/embed_shaders.c
	@mkdir -p $(dir $@)
	$(CC) -std=c11 -O1 -Wall -Werror -o $@ $<

$(BUILD)/gen/shaders_gen.c $(BUILD)/gen/shaders_gen.h &: $(BUILD)/embed_shaders $(SHADERS)
	@mkdir -p $(BUILD)/gen
	$(BUILD)/embed_shaders $(BUILD)/gen/shaders_gen $(SHADERS)

# The browser viewer's page (web/: HTML, JS, CSS) is compiled into the daemon the same way.
$(BUILD)/gen/page_gen.c $(BUILD)/gen/page_gen.h &: $(BUILD)/embed_shaders $(WEB)
	@mkdir -p $(BUILD)/gen
	$(BUILD)/embed_shaders --prefix page $(BUILD)/gen/page_gen $(WEB)

.PHONY: all test asan bench fuzz fuzz-smoke run install clean
all: $(BUILD)/bin/splatd $(BUILD)/bin/splat $(BUILD)/bin/splat-view $(BUILD)/libsplatclient.a $(BUILD)/libsplatclient.so $(TOOLS) \
     $(MPI_BIN)

$(BUILD)/libsplatclient.so: $(call obj,$(BUILD),$(CLIENT_LIB_SRC) $(PROTO_SRC))
	$(CC) -shared -Wl,-soname,libsplatclient.so.0 -Wl,--version-script=client/libsplatclient.map \
	  -o $@ $^ $(CLIENT_LIBS)

# The tests find the binaries and data through these variables.
TEST_ENV = SPLATD_BIN=$(abspath $(1)/bin/splatd) SPLAT_BIN=$(abspath $(1)/bin/splat) \
           SPLAT_VIEW_BIN=$(abspath $(1)/bin/splat-view) \
           SPLATD_TOOLS=$(abspath $(1)/tools) SPLATD_TESTDATA=$(abspath tests/data) \
           SPLATD_SHADERS=$(abspath shaders)

ASAN_ENV = ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 \
           LSAN_OPTIONS=suppressions=$(abspath tests/lsan.supp)

# make test: the plain run, the sanitizer run, and one closing line counting the tests of both
# with the wall time. tests/list names every program and its time limit; T selects programs
# and, after a colon, tests inside one: make test T='test_lod:test_octree* test_params'.
TEST_RUN = TEST_TOTALS=$(abspath $(BUILD)/test-totals) bash tests/run.sh
test: all $(TESTS) $(ASAN_TESTS) $(BUILD)/asan/bin/splatd $(BUILD)/asan/bin/splat \
      $(BUILD)/asan/bin/splat-view $(ASAN_TOOLS) $(MPI_ASAN_BIN)
	@rm -f $(BUILD)/test-totals; date +%s > $(BUILD)/test-start
	@$(call TEST_ENV,$(BUILD)) $(TEST_RUN) "plain" $(BUILD)/tests $(T)
	@$(call TEST_ENV,$(BUILD)/asan) $(ASAN_ENV) TEST_TIMEOUT_SCALE=3 $(TEST_RUN) "asan" $(BUILD)/asan/tests $(T)
	@awk -v t0=$$(cat $(BUILD)/test-start) -v t1=$$(date +%s) '{p += $$1; f += $$2; s += $$3} \
	  END {printf "total: %d passed, %d failed, %d skipped in %d s\n", p, f, s, t1 - t0}' $(BUILD)/test-totals

asan: $(ASAN_TESTS) $(BUILD)/asan/bin/splatd $(BUILD)/asan/bin/splat $(BUILD)/asan/bin/splat-view \
      $(ASAN_TOOLS) $(MPI_ASAN_BIN)
	@$(call TEST_ENV,$(BUILD)/asan) $(ASAN_ENV) TEST_TIMEOUT_SCALE=3 bash tests/run.sh "asan" $(BUILD)/asan/tests $(T)

bench: all $(BENCHES)
	@$(call TEST_ENV,$(BUILD)) SPLATD_BENCH=$(abspath $(BUILD)/bench) sh tests/bench/bench.sh

fuzz:
	@sh tests/fuzz/run.sh $(FUZZ_SECONDS)

# CI: every fuzz target must compile, link and survive a few seconds on its corpus (so that
# the fuzzers cannot rot unnoticed); two at a time.
FUZZ_SMOKE_SECONDS ?= 4
fuzz-smoke: $(BUILD)/gen/shaders_gen.c $(BUILD)/gen/page_gen.c
	@FUZZ_JOBS=$${FUZZ_JOBS:-2} sh tests/fuzz/run.sh $(FUZZ_SMOKE_SECONDS)

# make run RUN_ARGS=--force renders the demo's frames again (extra arguments go to `splat path`).
run: all
	@RUN_ARGS="$(RUN_ARGS)" sh deploy/run-demo.sh $(BUILD)/bin/splatd $(BUILD)/bin/splat

install: all
	install -d $(DESTDIR)$(PREFIX)/bin $(DESTDIR)$(PREFIX)/lib/pkgconfig $(DESTDIR)$(PREFIX)/include
	install -m 755 $(BUILD)/bin/splatd $(BUILD)/bin/splat $(BUILD)/bin/splat-view $(DESTDIR)$(PREFIX)/bin/
	if [ -x $(BUILD)/bin/splatd-mpi ]; then install -m 755 $(BUILD)/bin/splatd-mpi $(DESTDIR)$(PREFIX)/bin/; fi
	install -m 644 $(BUILD)/libsplatclient.a $(DESTDIR)$(PREFIX)/lib/
	install -m 755 $(BUILD)/libsplatclient.so $(DESTDIR)$(PREFIX)/lib/libsplatclient.so.0
	ln -sf libsplatclient.so.0 $(DESTDIR)$(PREFIX)/lib/libsplatclient.so
	install -m 644 client/splat_client.h $(DESTDIR)$(PREFIX)/include/
	sed 's|@PREFIX@|$(PREFIX)|g' client/splatclient.pc.in > $(DESTDIR)$(PREFIX)/lib/pkgconfig/splatclient.pc
	@# The dynamic linker's cache must learn the new library, or programs linked against it fail
	@# with "libsplatclient.so.0: cannot open shared object file". Staged installs skip it.
	@if [ -z "$(DESTDIR)" ]; then \
	   if [ "$$(id -u)" = 0 ]; then ldconfig; \
	   else echo "make install: run ldconfig as root so the loader finds libsplatclient.so.0"; fi; \
	 fi

clean:
	rm -rf $(BUILD) out

.SECONDARY:
-include $(shell find $(BUILD) -name '*.d' 2>/dev/null)
