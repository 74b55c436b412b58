# syntax=docker/dockerfile:1
#
# lodcloth serve: cloth instances stepping in real time, published on zenoh.
#
#   docker build -t lodcloth .
#   docker run --rm -p 7450:7450 -v lodcloth-cache:/var/lib/lodcloth lodcloth
#
# Needs BuildKit (the default builder of Docker 23 and later) for the cache
# mounts of the build stage.

# ---- build: the binary CI builds (`cargo build --release --locked`) ---------
# The tag is the exact toolchain of rust-toolchain.toml, so rustup finds it
# installed and only adds the file's components.
FROM rust:1.95.0-slim-bookworm AS builder
WORKDIR /build

# meshoptimizer (the `meshopt` crate, mesh cloths' level chains) is C++:
# the slim image has gcc but no g++.
RUN apt-get update \
    && apt-get install -y --no-install-recommends g++=4:12.2.0-3 \
    && rm -rf /var/lib/apt/lists/*

# The toolchain of rust-toolchain.toml, in a layer of its own that source
# changes do not invalidate.
COPY rust-toolchain.toml ./
RUN rustup toolchain install --no-self-update \
    && rustc --version \
    && cargo --version

# What the manifest needs to be read: build.rs compiles proto/ with protox (no
# protoc), and Cargo.toml's [[bench]] targets must exist even though they are
# not built. Its [[test]] targets name their paths, which cargo checks only
# when it builds them: tests/ is not needed.
COPY Cargo.toml Cargo.lock build.rs ./
COPY proto/ proto/
COPY benches/ benches/
COPY src/ src/
COPY crates/ crates/

# `lodcloth --version` and the lodcloth_build_info metric name the commit; the
# context has no .git, so build.rs takes it from here
# (docker build --build-arg REVISION=$(git rev-parse --short=12 HEAD) .).
ARG REVISION=unknown
# The registry and target dir live in cache mounts (not in the layer), so the
# binary is copied out of the cached target.
RUN --mount=type=cache,target=/usr/local/cargo/registry,sharing=locked \
    --mount=type=cache,target=/usr/local/cargo/git,sharing=locked \
    --mount=type=cache,target=/build/target,sharing=locked \
    LODCLOTH_GIT_REVISION="${REVISION}" cargo build --release --locked --bin lodcloth \
    && install -D -m 0755 target/release/lodcloth /out/lodcloth

# ---- runtime ------------------------------------------------------------------
# The binary needs only glibc, libm, libgcc_s and libstdc++ (meshoptimizer),
# all in the base image (apt itself needs libstdc++): no packages are installed.
FROM debian:bookworm-slim AS runtime

ARG VERSION=0.1.0
ARG REVISION=unknown
LABEL org.opencontainers.image.title="lodcloth" \
      org.opencontainers.image.description="Mass-spring cloth at several levels of detail, stepping in real time with coherent behaviour across levels, served over Eclipse Zenoh as protobuf" \
      org.opencontainers.image.version="${VERSION}" \
      org.opencontainers.image.revision="${REVISION}" \
      org.opencontainers.image.licenses="MIT OR Apache-2.0" \
      org.opencontainers.image.base.name="docker.io/library/debian:bookworm-slim"

# A fixed uid/gid, so that a bind-mounted cache directory can be chowned to
# it on the host (chown 10001:10001 DIR). The cache directory is created here
# so a named volume starts out owned by the user.
RUN groupadd --gid 10001 lodcloth \
    && useradd --uid 10001 --gid lodcloth --no-log-init --no-create-home \
       --home-dir /var/lib/lodcloth --shell /usr/sbin/nologin lodcloth \
    && install -d -o lodcloth -g lodcloth -m 0755 /var/lib/lodcloth /var/lib/lodcloth/cache

WORKDIR /opt/lodcloth
COPY --from=builder /out/lodcloth /usr/local/bin/lodcloth
# Scene paths in the config are relative to this working directory. Owned by
# root: the daemon only reads them.
COPY config/scenes/ config/scenes/
COPY config/meshes/ config/meshes/
COPY config/surfaces/ config/surfaces/
COPY config/docker.toml config/docker.toml
# The secure deployment (README "Reliability and security"): certificates are
# mounted at /run/secrets, never baked in.
COPY config/docker-secure.toml config/docker-secure.toml

# JSON log lines for log collectors (`false` for text). clap reads this flag
# as a boolean literal: `true` or `false`, not 1/0.
ENV LODCLOTH_LOG_JSON=true

VOLUME ["/var/lib/lodcloth"]
# 7450: zenoh; 7451/udp: zenoh over QUIC with mutual TLS (config/docker-secure.toml); 7460:
# /metrics and /healthz (config/docker.toml [http]). 8080 and 8765 when the same image runs `view --listen
# 0.0.0.0:8080` or `foxglove --host 0.0.0.0` beside the daemon (README).
EXPOSE 7450/tcp 7451/udp 7460/tcp 8080/tcp 8765/tcp
USER 10001:10001

# A client session to the daemon's own endpoint; exits 0 when every instance
# answers. (It inherits ENV, so LODCLOTH_CONNECT set for `serve` is
# overridden by the explicit --connect.)
HEALTHCHECK --interval=30s --timeout=15s --start-period=30s --retries=3 \
    CMD ["lodcloth", "health", "--connect", "tcp/127.0.0.1:7450"]

ENTRYPOINT ["lodcloth"]
CMD ["serve", "--config", "config/docker.toml"]
