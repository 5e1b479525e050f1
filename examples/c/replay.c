/* Replays the committed scenario (scenario.bin) through the SatMap C API over static,
 * caller-owned regions, checks every published map frame's E2E protection and compares its
 * digest with the Rust run. Exit status 0 only when every check passes.
 *
 * Usage: replay <bundle> <calibration.toml> <scenario.bin> <expected dir> [<key.pub>] [memcheck]
 *
 * With <key.pub> (a `satmap-sim keygen` public key; `make test-c` signs a copy of the bundle
 * with its secret half) the runtime is created the way an ECU creates it: satmap_create_trusted
 * with SATMAP_TRUST_SIGNED, the signature read from <bundle>.sig; a pin on another digest is
 * refused first (SATMAP_STATUS_BUNDLE_NOT_PINNED).
 *
 * Digests are bit-identical within a family of graph kernels, not across families: the replay
 * asks the library which family this CPU runs (satmap_kernel_family()) and compares with
 * <expected dir>/expected-<family>.txt.
 *
 * `memcheck` (the run under valgrind): the first two frames (one whole step, one staged), CRC
 * checked, no bit-flip sweep and digests printed, not compared: valgrind's CPU has no AVX-512,
 * so tract picks other matmul kernels and the floats (hence the digest) differ in the last
 * bits. The native run compares every digest.
 *
 * scenario.bin (little-endian): "SMSCEN01", then u32 frames, image_sets, image_w, image_h,
 * sat_w, sat_h; image_sets x (6 camera images, u8 RGB HWC, then the satellite crop); then
 * frames x 84-byte records: u64 sequence, u64 timestamp_us, f64 x_m, f64 y_m, f64 yaw_rad,
 * f32 acceleration[3], f32 rotation_rate[3], f32 velocity[3], u32 image_set,
 * u8 camera_present_mask, u8 satellite_present, u8 staged, u8 reserved. */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "satmap.h"

/* The caller-owned regions, sized from memory_layout.toml (satmap_region_info says the same;
 * checked below). A linker script would place these in the ECU's RAM sections. A runtime built
 * with another layout (layouts/nano-f16-bev.toml halves camera_bev and satellite_bev) has other
 * sizes: the check below then stops with the region named. */
#define REGION(name, bytes) static _Alignas(SATMAP_REGION_ALIGN) uint8_t name[bytes]
REGION(value_features, 368640);
REGION(gkt_lut, 2345600);
REGION(bev_query, 3276800);
REGION(gkt_weights, 768000);
REGION(gathered, 3276800);
REGION(camera_bev, 3276800);
REGION(satellite_crop, 60000);
REGION(satellite_bev, 3276800);
REGION(class_logits, 1200);
REGION(points, 16000);

static uint8_t wire[SATMAP_MAX_WIRE_BYTES];

#define MAX_FRAMES 16

static int fail(const char *what) {
  fprintf(stderr, "replay: %s\n", what);
  return 1;
}

static uint32_t u32_at(const uint8_t *p) {
  uint32_t v;
  memcpy(&v, p, 4);
  return v;
}

static uint8_t *read_file(const char *path, size_t *len) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  fseek(f, 0, SEEK_END);
  long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  /* One byte more, NUL, so that text can be parsed in place. */
  uint8_t *buf = n > 0 ? malloc((size_t)n + 1) : NULL;
  if (buf && fread(buf, 1, (size_t)n, f) != (size_t)n) {
    free(buf);
    buf = NULL;
  }
  if (buf) buf[n] = 0;
  fclose(f);
  *len = buf ? (size_t)n : 0;
  return buf;
}

static const char *status_name(SatmapStatus s) {
  switch (s) {
    case SATMAP_STATUS_OK: return "OK";
    case SATMAP_STATUS_REGION_TOO_SMALL: return "REGION_TOO_SMALL";
    case SATMAP_STATUS_BUNDLE: return "BUNDLE";
    case SATMAP_STATUS_CALIBRATION: return "CALIBRATION";
    case SATMAP_STATUS_FRAME_REJECTED: return "FRAME_REJECTED";
    case SATMAP_STATUS_STEP_IN_PROGRESS: return "STEP_IN_PROGRESS";
    case SATMAP_STATUS_CRC_MISMATCH: return "CRC_MISMATCH";
    case SATMAP_STATUS_BUNDLE_UNSIGNED: return "BUNDLE_UNSIGNED";
    case SATMAP_STATUS_BUNDLE_SIGNATURE: return "BUNDLE_SIGNATURE";
    case SATMAP_STATUS_BUNDLE_NOT_PINNED: return "BUNDLE_NOT_PINNED";
    case SATMAP_STATUS_LUT_CORRUPT: return "LUT_CORRUPT";
    default: return "other";
  }
}

/* The 32 key bytes of a `.pub` file: 64 lowercase hex digits, then an optional newline. */
static int read_public_key(const char *path, uint8_t key[32]) {
  size_t len = 0;
  uint8_t *text = read_file(path, &len);
  int ok = text && (len == 64 || (len == 65 && text[64] == '\n'));
  for (size_t i = 0; ok && i < 64; i++) {
    uint8_t c = text[i];
    int nibble = c >= '0' && c <= '9' ? c - '0' : c >= 'a' && c <= 'f' ? c - 'a' + 10 : -1;
    if (nibble < 0) ok = 0;
    else if (i % 2 == 0) key[i / 2] = (uint8_t)(nibble << 4);
    else key[i / 2] |= (uint8_t)nibble;
  }
  free(text);
  return ok;
}

int main(int argc, char **argv) {
  int memcheck = argc >= 6 && strcmp(argv[argc - 1], "memcheck") == 0;
  const char *public_key_path = argc - memcheck == 6 ? argv[5] : NULL;
  if (argc - memcheck != 5 && argc - memcheck != 6)
    return fail("usage: replay <bundle> <calibration.toml> <scenario.bin> <expected dir> "
                "[<key.pub>] [memcheck]");
  char expected_path[4096];
  const char *family = satmap_kernel_family();
  if (snprintf(expected_path, sizeof expected_path, "%s/expected-%s.txt", argv[4], family) >=
      (int)sizeof expected_path)
    return fail("expected dir path too long");
  printf("replay: kernel family %s, digests from %s\n", family, expected_path);

  uint8_t *regions_mem[SATMAP_REGION_COUNT] = {value_features, gkt_lut,     bev_query,
                                               gkt_weights,    gathered,    camera_bev,
                                               satellite_crop, satellite_bev, class_logits,
                                               points};
  size_t regions_len[SATMAP_REGION_COUNT] = {
      sizeof value_features, sizeof gkt_lut,        sizeof bev_query,    sizeof gkt_weights,
      sizeof gathered,       sizeof camera_bev,     sizeof satellite_crop, sizeof satellite_bev,
      sizeof class_logits,   sizeof points};
  SatmapRegion regions[SATMAP_REGION_COUNT];
  for (size_t i = 0; i < SATMAP_REGION_COUNT; i++) {
    SatmapRegionInfo info;
    if (satmap_region_info(i, &info) != SATMAP_STATUS_OK) return fail("region info");
    if (info.bytes != regions_len[i]) {
      fprintf(stderr, "replay: region %s is %zu bytes in memory_layout.toml, %zu here\n",
              info.name, info.bytes, regions_len[i]);
      return 1;
    }
    regions[i].data = regions_mem[i];
    regions[i].len = regions_len[i];
  }

  SatmapRuntime *rt = NULL;
  /* One byte short: refused, naming nothing but the status (the Rust error names the region). */
  regions[3].len -= 1;
  SatmapStatus s = satmap_create(regions, SATMAP_REGION_COUNT, argv[1], argv[2], &rt);
  if (s != SATMAP_STATUS_REGION_TOO_SMALL || rt != NULL) return fail("short region accepted");
  regions[3].len += 1;
  if (public_key_path) {
    SatmapBundleTrust trust = {.kind = SATMAP_TRUST_PINNED};
    memset(trust.pinned_sha256, 0xA5, sizeof trust.pinned_sha256);
    s = satmap_create_trusted(regions, SATMAP_REGION_COUNT, argv[1], argv[2], &trust, &rt);
    if (s != SATMAP_STATUS_BUNDLE_NOT_PINNED || rt != NULL) return fail("another pin accepted");
    trust.kind = SATMAP_TRUST_SIGNED;
    if (!read_public_key(public_key_path, trust.public_key)) return fail("unreadable public key");
    s = satmap_create_trusted(regions, SATMAP_REGION_COUNT, argv[1], argv[2], &trust, &rt);
    if (s == SATMAP_STATUS_OK) printf("replay: bundle signature verified (%s)\n", public_key_path);
  } else {
    s = satmap_create(regions, SATMAP_REGION_COUNT, argv[1], argv[2], &rt);
  }
  if (s != SATMAP_STATUS_OK) {
    fprintf(stderr, "replay: satmap_create: %s (%d)\n", status_name(s), (int)s);
    return 1;
  }

  size_t scen_len = 0, exp_len = 0;
  uint8_t *scen = read_file(argv[3], &scen_len);
  uint8_t *exp = read_file(expected_path, &exp_len);
  /* Under memcheck the digests are not compared (valgrind's CPU is another kernel family, whose
   * file may not exist). */
  if (!scen || (!exp && !memcheck) || scen_len < 32 || memcmp(scen, "SMSCEN01", 8) != 0) {
    satmap_destroy(rt);
    free(scen);
    free(exp);
    return fail("cannot read the scenario or the expected digests");
  }
  uint32_t frames = u32_at(scen + 8), sets = u32_at(scen + 12), w = u32_at(scen + 16),
           h = u32_at(scen + 20), sw = u32_at(scen + 24), sh = u32_at(scen + 28);
  size_t image_bytes = (size_t)w * h * 3, sat_bytes = (size_t)sw * sh * 3;
  size_t set_bytes = 6 * image_bytes + sat_bytes;
  size_t records = 32 + sets * set_bytes;
  if (frames > MAX_FRAMES || scen_len != records + frames * 84) {
    satmap_destroy(rt);
    free(scen);
    free(exp);
    return fail("scenario size does not match its header");
  }

  /* expected-<family>.txt: one "<sequence> <digest hex>" line per frame. */
  uint64_t want_seq[MAX_FRAMES], want_digest[MAX_FRAMES];
  size_t n_want = 0;
  char *line = exp ? strtok((char *)exp, "\n") : NULL;
  while (line && n_want < MAX_FRAMES) {
    if (sscanf(line, "%" SCNu64 " %" SCNx64, &want_seq[n_want], &want_digest[n_want]) == 2) n_want++;
    line = strtok(NULL, "\n");
  }

  int bad = 0;
  uint32_t run = memcheck && frames > 2 ? 2 : frames;
  for (uint32_t k = 0; k < run; k++) {
    const uint8_t *r = scen + records + (size_t)k * 84;
    SatmapFrame f;
    memset(&f, 0, sizeof f);
    memcpy(&f.sequence, r, 8);
    memcpy(&f.timestamp_us, r + 8, 8);
    memcpy(f.position_m, r + 16, 16);
    memcpy(&f.yaw_rad, r + 32, 8);
    memcpy(f.acceleration_mps2, r + 40, 12);
    memcpy(f.rotation_rate_radps, r + 52, 12);
    memcpy(f.velocity_mps, r + 64, 12);
    uint32_t set = u32_at(r + 76);
    uint8_t present = r[80], sat_present = r[81], staged = r[82];
    if (set >= sets) {
      bad = 1;
      break;
    }
    const uint8_t *images = scen + 32 + set * set_bytes;
    for (int c = 0; c < SATMAP_NUM_CAMERAS; c++) {
      f.cameras[c].rgb = (present >> c) & 1 ? images + c * image_bytes : NULL;
      f.cameras[c].len = image_bytes;
      f.cameras[c].width_px = w;
      f.cameras[c].height_px = h;
      f.cameras[c].capture_us = f.timestamp_us;
      f.cameras[c].valid = 1;
    }
    f.satellite_rgb = sat_present ? images + 6 * image_bytes : NULL;
    f.satellite_len = sat_bytes;

    if (staged) {
      s = satmap_step_begin(rt, &f);
      int slices = 0;
      SatmapSliceInfo info = {0};
      /* A second frame while the step is in progress is refused; the step goes on. */
      if (s == SATMAP_STATUS_OK && satmap_step_begin(rt, &f) != SATMAP_STATUS_STEP_IN_PROGRESS) bad = 1;
      while (s == SATMAP_STATUS_OK) {
        s = satmap_step_run_next(rt, &f, &info);
        slices++;
        if (info.remaining == 0) break;
      }
      if (s == SATMAP_STATUS_OK) s = satmap_step_finish(rt);
      printf("frame %" PRIu64 ": staged, %d slices\n", f.sequence, slices);
    } else {
      s = satmap_step(rt, &f);
    }
    if (s != SATMAP_STATUS_OK) {
      char msg[256];
      satmap_last_error(rt, msg, sizeof msg);
      fprintf(stderr, "replay: frame %" PRIu64 ": %s (%d): %s\n", f.sequence, status_name(s), (int)s, msg);
      bad = 1;
      continue;
    }

    size_t n = 0;
    if (satmap_map_frame(rt, SATMAP_DEFAULT_DATA_ID, wire, sizeof wire, &n) != SATMAP_STATUS_OK) {
      bad = 1;
      continue;
    }
    uint64_t seq = 0;
    uint16_t counter = 0;
    int crc_ok = satmap_check_map_frame(wire, n, SATMAP_DEFAULT_DATA_ID, &seq, &counter) == SATMAP_STATUS_OK;
    /* Every single-bit flip of the first received frame must fail the check (tests/integration/c_api.rs
     * flips every frame's bits; under valgrind one frame keeps the run short). */
    size_t flips_caught = 0, flips = k == 0 && !memcheck ? n * 8 : 0;
    for (size_t bit = 0; bit < flips; bit++) {
      wire[bit / 8] ^= (uint8_t)(1u << (bit % 8));
      SatmapStatus c = satmap_check_map_frame(wire, n, SATMAP_DEFAULT_DATA_ID, NULL, NULL);
      if (c == SATMAP_STATUS_CRC_MISMATCH || c == SATMAP_STATUS_WIRE_INVALID) flips_caught++;
      wire[bit / 8] ^= (uint8_t)(1u << (bit % 8));
    }
    uint64_t digest;
    memcpy(&digest, wire + 28, 8);
    uint32_t health;
    memcpy(&health, wire + 36, 4);
    int match = memcheck || (k < n_want && want_seq[k] == f.sequence && want_digest[k] == digest);
    printf("frame %" PRIu64 ": %zu bytes, counter %u, %u elements, health 0x%05x, digest %016" PRIx64
           " (rust %016" PRIx64 ") %s, crc %s, bit flips caught %zu/%zu\n",
           f.sequence, n, counter, wire[42], health, digest, k < n_want ? want_digest[k] : 0,
           memcheck ? "not compared" : match ? "equal" : "DIFFERENT", crc_ok ? "ok" : "FAILED", flips_caught, flips);
    if (!match || !crc_ok || seq != f.sequence || flips_caught != flips) bad = 1;
  }

  satmap_destroy(rt);
  free(scen);
  free(exp);
  if (bad || (!memcheck && n_want != frames)) return fail("FAILED");
  if (memcheck)
    printf("replay: %u frames under memcheck, every CRC check passed\n", run);
  else
    printf("replay: %u frames, digests equal to the Rust run, every CRC check passed\n", run);
  return 0;
}
