//! [`SyntheticRouteImagery`]: satellite-like imagery of the ground around a [`SyntheticRoute`](super::SyntheticRoute).

use super::*;

/// A kind of field: base colour, row-stripe contrast, texture contrast, bare-soil patchiness,
/// extra tree density.
pub(super) struct FieldKind {
    pub(super) base: Vec3A,
    pub(super) stripes: f32,
    pub(super) texture: f32,
    pub(super) patches: f32,
    pub(super) trees: f32,
}

pub(super) const fn kind(
    base: [f32; 3],
    stripes: f32,
    texture: f32,
    patches: f32,
    trees: f32,
) -> FieldKind {
    FieldKind {
        base: Vec3A::from_array(base),
        stripes,
        texture,
        patches,
        trees,
    }
}

/// Field kinds: green crop, young crop (soil between the rows), ripe cereal, ploughed soil,
/// dark soil, pasture, dry meadow, woodland; drawn by hash (`FIELD_DRAW`, per 16th).
pub(super) const FIELD_KINDS: [FieldKind; 8] = [
    kind([82.0, 104.0, 52.0], 0.10, 0.9, 0.10, 0.0),
    kind([120.0, 124.0, 78.0], 0.20, 0.8, 0.15, 0.0),
    kind([178.0, 160.0, 106.0], 0.07, 0.6, 0.05, 0.0),
    kind([124.0, 102.0, 78.0], 0.16, 1.0, 0.0, 0.0),
    kind([98.0, 83.0, 66.0], 0.09, 1.0, 0.0, 0.0),
    kind([98.0, 116.0, 64.0], 0.0, 1.1, 0.30, 0.05),
    kind([146.0, 138.0, 94.0], 0.02, 1.0, 0.20, 0.08),
    kind([70.0, 86.0, 50.0], 0.0, 1.2, 0.0, 0.45),
];
pub(super) const FIELD_DRAW: [u8; 16] = [0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 5, 5, 5, 6, 7, 7];
/// Bare soil showing through grass and crops.
pub(super) const SOIL: Vec3A = Vec3A::new(128.0, 110.0, 86.0);
pub(super) const ASPHALT: Vec3A = Vec3A::new(72.0, 73.0, 76.0);
pub(super) const PAINT: Vec3A = Vec3A::new(222.0, 222.0, 214.0);
pub(super) const GRAVEL: Vec3A = Vec3A::new(140.0, 133.0, 118.0);
pub(super) const VERGE: Vec3A = Vec3A::new(104.0, 116.0, 70.0);
pub(super) const TRACK: Vec3A = Vec3A::new(132.0, 120.0, 96.0);
pub(super) const TREE_DARK: Vec3A = Vec3A::new(30.0, 44.0, 26.0);
pub(super) const TREE_LIGHT: Vec3A = Vec3A::new(62.0, 84.0, 44.0);

/// Half the asphalt width, metres.
pub(super) const ROAD_HALF_M: f32 = 0.5 * ROAD_WIDTH_M as f32;
/// Offset of the edge lines' centre from the centre line, metres.
pub(super) const EDGE_LINE_M: f32 = ROAD_HALF_M - 0.3;
/// Width of the edge lines, metres.
pub(super) const EDGE_LINE_WIDTH_M: f32 = 0.2;
/// Width of the centre line, metres.
pub(super) const CENTRE_LINE_WIDTH_M: f32 = 0.15;
/// Centre-line dash, metres.
pub(super) const DASH_M: f64 = 3.0;
/// Centre-line dash plus gap, metres.
pub(super) const DASH_PERIOD_M: f64 = 12.0;
/// Default pixel footprint of [`SyntheticRoute::imagery`], metres (the default pack GSD).
pub const DEFAULT_PIXEL_M: f64 = 0.15;

/// The 3x3 jittered Voronoi sites around the last field cell looked up, with each field's
/// hash and row vector (direction over spacing, per metre).
#[derive(Clone, Copy)]
pub(super) struct FieldSites {
    pub(super) cell: Option<(i32, i32)>,
    /// Relative to the cell's corner, cells.
    pub(super) sites: [Vec2; 9],
    pub(super) hashes: [u32; 9],
    pub(super) rows: [DVec2; 9],
    /// The last nearest and second-nearest sites, and the bisector distance per unit of
    /// their squared-distance difference, metres.
    pub(super) pair: (usize, usize),
    pub(super) edge_scale: f32,
}

/// What [`SyntheticRouteImagery::field`] finds at a point.
pub(super) struct FieldAt {
    pub(super) hash: u32,
    /// Distance to the field's boundary, metres.
    pub(super) edge_m: f32,
    /// Across-row direction over the row spacing, per metre.
    pub(super) rows: DVec2,
}

/// Noise values at one point (see [`OCTAVE_PERIODS_M`]).
pub(super) struct Noise {
    /// Octave 0: warp x, warp y, moisture, large tree density.
    pub(super) coarse: Vec4,
    /// Octave 1: small tree density, bare-soil patches.
    pub(super) mid: Vec4,
    /// Octaves 1..3 (z, x, x): texture, coarse to fine.
    pub(super) tex: Vec3A,
    /// Octaves 1..3 (w, y, y): canopy texture, coarse to fine.
    pub(super) crown: Vec3A,
    /// Per-0.25 m grain in [-0.5, 0.5).
    pub(super) grain: f32,
}

/// Satellite-like imagery of a [`SyntheticRoute`]'s surroundings; source coordinates are
/// route-frame metres. Caches the last grid cells looked up (samples arrive row by row).
pub struct SyntheticRouteImagery<'a> {
    route: &'a SyntheticRoute,
    frame: EnuFrame,
    seed: u32,
    lattice: Box<Lattice>,
    octaves: [Octave; 4],
    lanes: OctaveLanes,
    /// The current road cell's corner, metres, and the octaves' lattice coordinates there
    /// (modulo the lattice side).
    corner: DVec2,
    base_x: Vec4,
    base_y: Vec4,
    /// Pixel footprint the paint and the asphalt's edges are box-filtered over, metres.
    pixel_m: f32,
    inv_pixel: f32,
    road_cell: (i32, i32),
    road_range: (u32, u32),
    fields: FieldSites,
}

impl<'a> SyntheticRouteImagery<'a> {
    /// The imagery of `route` for packs of `pixel_m` metres per pixel (the road's edges and
    /// markings are box-filtered over one pixel; clamped to 0.01..=10 m).
    #[must_use]
    pub fn new(route: &'a SyntheticRoute, pixel_m: f64) -> Self {
        let mut z = route.seed ^ 0x001a_6e5e_edf1_e1d5_u64;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        let seed = (z ^ (z >> 31)) as u32;
        let lattice: Box<Lattice> = (0..LATTICE_SIDE * LATTICE_SIDE)
            .map(|i| {
                let (x, y) = ((i % LATTICE_SIDE) as i32, (i / LATTICE_SIDE) as i32);
                let (a, b) = (hash2(seed, x, y), hash2(seed ^ 0x7a11_ce5e, x, y));
                let half = |h: u32| (h & 0xffff) as f32 / 65_535.0;
                Vec4::new(half(a), half(a >> 16), half(b), half(b >> 16))
            })
            .collect::<Vec<_>>()
            .into_boxed_slice()
            .try_into()
            .unwrap_or_else(|_| unreachable!("the lattice has LATTICE_SIDE^2 points"));
        let side = LATTICE_SIDE as f64;
        let octaves = std::array::from_fn(|k| {
            let h = hash2(seed ^ 0x00c7_a7e5, k as i32, 0);
            // Rotations spread over the half turn, so no two octaves share a lattice axis.
            let r =
                DVec2::from_angle(PI * (k as f64 * 0.382 + 0.1 * unit(h))) / OCTAVE_PERIODS_M[k];
            Octave {
                row_x: DVec2::new(r.x, -r.y),
                row_y: DVec2::new(r.y, r.x),
                offset: DVec2::new(unit(remix(h)), unit(remix(remix(h)))) * side,
            }
        });
        let lane = |f: fn(&Octave) -> f64| {
            Vec4::from_array(std::array::from_fn(|k| f(&octaves[k]) as f32))
        };
        let lanes = OctaveLanes {
            xx: lane(|o| o.row_x.x),
            xy: lane(|o| o.row_x.y),
            yx: lane(|o| o.row_y.x),
            yy: lane(|o| o.row_y.y),
        };
        // A cell beyond any route (i32::MIN) is empty, so the stale range is right for it;
        // the lattice base is set with the first sample's cell.
        let road_cell = (i32::MIN, i32::MIN);
        let pixel_m = if pixel_m.is_finite() {
            pixel_m.clamp(0.01, 10.0) as f32
        } else {
            DEFAULT_PIXEL_M as f32
        };
        Self {
            route,
            frame: route.frame,
            seed,
            lattice,
            octaves,
            lanes,
            corner: DVec2::NAN,
            base_x: Vec4::ZERO,
            base_y: Vec4::ZERO,
            pixel_m,
            inv_pixel: 1.0 / pixel_m,
            road_cell,
            road_range: route.grid.cell(road_cell.0, road_cell.1),
            fields: FieldSites {
                cell: None,
                sites: [Vec2::ZERO; 9],
                hashes: [0; 9],
                rows: [DVec2::ZERO; 9],
                pair: (usize::MAX, usize::MAX),
                edge_scale: 0.0,
            },
        }
    }

    /// Distance from `p` to the centre line and arc length of the nearest point, if within
    /// [`ROAD_REACH_M`].
    #[inline]
    fn road(&mut self, p: DVec2) -> Option<(f64, f64)> {
        let cell = (floor_i32(p.x / CELL_M), floor_i32(p.y / CELL_M));
        if cell != self.road_cell {
            self.road_cell = cell;
            self.road_range = self.route.grid.cell(cell.0, cell.1);
            self.corner = DVec2::new(f64::from(cell.0), f64::from(cell.1)) * CELL_M;
            let side = LATTICE_SIDE as f64;
            let wrap = |v: f64| (v - side * f64::from(floor_i32(v * (1.0 / side)))) as f32;
            let base = |k: usize| {
                let o = &self.octaves[k];
                let q = DVec2::new(o.row_x.dot(self.corner), o.row_y.dot(self.corner)) + o.offset;
                (wrap(q.x), wrap(q.y))
            };
            let b: [(f32, f32); 4] = std::array::from_fn(base);
            self.base_x = Vec4::new(b[0].0, b[1].0, b[2].0, b[3].0);
            self.base_y = Vec4::new(b[0].1, b[1].1, b[2].1, b[3].1);
        }
        let (start, end) = self.road_range;
        let mut best = ROAD_REACH_M * ROAD_REACH_M;
        let mut s = f64::NAN;
        for seg in &self.route.grid.segments[start as usize..end as usize] {
            let v = p - seg.a;
            let t = v.dot(seg.dir).clamp(0.0, seg.len);
            let d2 = (v - seg.dir * t).length_squared();
            if d2 < best {
                best = d2;
                s = seg.s0 + t;
            }
        }
        s.is_finite().then(|| (best.sqrt(), s))
    }

    /// The field containing `q` (warped metres).
    #[inline]
    fn field(&mut self, q: DVec2) -> FieldAt {
        let g = q * (1.0 / FIELD_CELL_M);
        let cell = (floor_i32(g.x), floor_i32(g.y));
        if self.fields.cell != Some(cell) {
            let salt = self.seed ^ 0x00f1_e1d5;
            for k in 0..9 {
                let (cx, cy) = (
                    cell.0.wrapping_add(k as i32 % 3 - 1),
                    cell.1.wrapping_add(k as i32 / 3 - 1),
                );
                let h = hash2(salt, cx, cy);
                let h2 = remix(h);
                let hash = remix(h2);
                self.fields.sites[k] = Vec2::new(
                    (k % 3) as f32 - 1.0 + 0.1 + 0.8 * unit(h) as f32,
                    (k / 3) as f32 - 1.0 + 0.1 + 0.8 * unit(h2) as f32,
                );
                let r = remix(hash);
                let spacing_m = 1.2 + 2.5 * unit(r);
                self.fields.rows[k] = DVec2::from_angle(PI * unit(remix(r))) / spacing_m;
                self.fields.hashes[k] = hash;
            }
            self.fields.cell = Some(cell);
            self.fields.pair = (usize::MAX, usize::MAX);
        }
        // In f32 about the cell's corner (sites within 2 cells of it).
        let base = DVec2::new(f64::from(cell.0), f64::from(cell.1));
        let local = (g - base).as_vec2();
        let (mut d1, mut d2) = (f32::INFINITY, f32::INFINITY);
        let (mut i1, mut i2) = (0, 0);
        for (k, site) in self.fields.sites.iter().enumerate() {
            let d = (local - *site).length_squared();
            if d < d1 {
                (d2, i2) = (d1, i1);
                (d1, i1) = (d, k);
            } else if d < d2 {
                (d2, i2) = (d, k);
            }
        }
        // Distance to the bisector of the two nearest sites (the pair rarely changes from one
        // sample to the next: its scale is kept).
        if self.fields.pair != (i1, i2) {
            let gap = (self.fields.sites[i2] - self.fields.sites[i1]).length();
            self.fields.pair = (i1, i2);
            self.fields.edge_scale = FIELD_CELL_M as f32 / (2.0 * gap.max(1e-6));
        }
        FieldAt {
            hash: self.fields.hashes[i1],
            edge_m: (d2 - d1) * self.fields.edge_scale,
            rows: self.fields.rows[i1],
        }
    }

    /// Value noise of the four octaves at `p` (in the road cell of the last [`Self::road`]
    /// call): four channels each, in [0, 1].
    #[inline]
    fn octaves(&self, p: DVec2) -> [Vec4; 4] {
        /// 1.5 * 2^23: adding it rounds an f32 to an integer held in the low mantissa bits.
        const MAGIC: f32 = 12_582_912.0;
        let l = (p - self.corner).as_vec2();
        let o = &self.lanes;
        let x = self.base_x + o.xx * l.x + o.xy * l.y;
        let y = self.base_y + o.yx * l.x + o.yy * l.y;
        // Floors by rounding x - 0.5 (a tie gives the cell below with a fraction of 1: the
        // same value, as value noise is continuous).
        let (rx, ry) = ((x - 0.5) + MAGIC, (y - 0.5) + MAGIC);
        let (fx, fy) = (x - (rx - MAGIC), y - (ry - MAGIC));
        let u = fx * fx * (3.0 - 2.0 * fx);
        let v = fy * fy * (3.0 - 2.0 * fy);
        let (rx, ry, u, v) = (rx.to_array(), ry.to_array(), u.to_array(), v.to_array());
        [
            self.lattice_at(rx[0], ry[0], u[0], v[0]),
            self.lattice_at(rx[1], ry[1], u[1], v[1]),
            self.lattice_at(rx[2], ry[2], u[2], v[2]),
            self.lattice_at(rx[3], ry[3], u[3], v[3]),
        ]
    }

    /// Bilinear blend of the lattice cell whose corner is held in the low bits of `rx`, `ry`
    /// (see [`Self::octaves`]), at smoothed fractions `u`, `v`.
    #[inline(always)]
    fn lattice_at(&self, rx: f32, ry: f32, u: f32, v: f32) -> Vec4 {
        // Two's complement masking is the lattice's wrap-around.
        let mask = LATTICE_SIDE as u32 - 1;
        let (x0, y0) = (rx.to_bits() & mask, ry.to_bits() & mask);
        let (x1, y1) = ((x0 + 1) & mask, (y0 + 1) & mask);
        let at = |x: u32, y: u32| self.lattice[(y * LATTICE_SIDE as u32 + x) as usize];
        let top = at(x0, y0).lerp(at(x1, y0), u);
        let bottom = at(x0, y1).lerp(at(x1, y1), u);
        top.lerp(bottom, v)
    }

    /// Colour of the ground at route-frame point `p`, 0..255 per channel (unclamped).
    fn colour(&mut self, p: DVec2) -> Vec3A {
        let road = self.road(p);
        let (g, ig) = (self.pixel_m, self.inv_pixel);
        let [coarse, mid, n2, n3] = self.octaves(p);
        let noise = Noise {
            coarse,
            mid,
            tex: Vec3A::new(mid.z, n2.x, n3.x),
            crown: Vec3A::new(mid.w, n2.y, n3.y),
            // Sensor-like grain: one hash on a 0.25 m lattice (offset by half a cell from the
            // road grid's corners).
            grain: unit(hash2(
                self.seed ^ 0x6a1e,
                floor_i32(p.x * 4.0 + 0.5),
                floor_i32(p.y * 4.0 + 0.5),
            )) as f32
                - 0.5,
        };
        let Some((d, s)) = road else {
            return self.terrain(p, f32::INFINITY, &noise);
        };
        let d32 = d as f32;
        let (moist, tex) = (noise.coarse.z, noise.tex);
        // Under full asphalt the terrain is not seen: skip it.
        let mut c = if d32 < ROAD_HALF_M - 0.5 * g {
            ASPHALT
        } else {
            let t = self.terrain(p, d32, &noise);
            let verge = 1.0 + 0.25 * (tex.z - 0.5) + 0.1 * noise.grain;
            let t = t.lerp(VERGE * verge, smoothstep(7.5, 5.0, d32));
            t.lerp(GRAVEL * verge, smoothstep(4.7, 4.1, d32))
        };
        let wheel = smoothstep(0.35, 0.1, ((d32 - 0.5 * ROAD_HALF_M).abs() - 0.85).abs());
        let asphalt = ASPHALT
            * (1.0 + 0.12 * (tex.z - 0.5) + 0.08 * (tex.x - 0.5) + 0.06 * (moist - 0.5)
                - 0.05 * wheel
                + 0.08 * noise.grain);
        c = c.lerp(asphalt, box_cover(d32, ROAD_WIDTH_M as f32, g, ig));
        // Dash centres at 1.5 m of each 12 m period; `along` is wrapped to [-6, 6) m.
        let u = (s - 0.5 * DASH_M) * (1.0 / DASH_PERIOD_M) + 0.5;
        let along = ((u - f64::from(floor_i32(u)) - 0.5) * DASH_PERIOD_M) as f32;
        let paint = box_cover(d32 - EDGE_LINE_M, EDGE_LINE_WIDTH_M, g, ig).max(
            box_cover(d32, CENTRE_LINE_WIDTH_M, g, ig) * box_cover(along, DASH_M as f32, g, ig),
        );
        if paint > 0.0 {
            c = c.lerp(PAINT * (0.92 + 0.12 * tex.y), paint);
        }
        c
    }

    /// The farmland at `p`, `road_d` metres from the centre line.
    #[inline]
    fn terrain(&mut self, p: DVec2, road_d: f32, n: &Noise) -> Vec3A {
        let [warp_x, warp_y, moist, trees_big] = n.coarse.to_array();
        let (trees_small, patch) = (n.mid.x, n.mid.y);
        let q = p + DVec2::new(f64::from(warp_x) - 0.5, f64::from(warp_y) - 0.5) * 60.0;
        let field = self.field(q);
        let kind = &FIELD_KINDS[usize::from(FIELD_DRAW[(field.hash >> 28) as usize])];
        let mut c = kind.base * (0.9 + 0.2 * unit(remix(field.hash)) as f32);
        c = c.lerp(SOIL, kind.patches * smoothstep(0.45, 0.75, patch));
        // Rows: a triangle wave across the field's own direction and spacing.
        let t = q.dot(field.rows);
        let tri = (2.0 * (t - f64::from(floor_i32(t))) - 1.0).abs() as f32;
        let texture = Vec3A::new(0.25, 0.35, 0.45).dot(n.tex - 0.5) + 0.3 * n.grain;
        c *= 1.0 + kind.stripes * (tri - 0.5) + 0.4 * kind.texture * texture + 0.12 * (moist - 0.5);
        // Field edges: a narrow worn track or grass strip.
        c = c.lerp(TRACK, 0.7 * smoothstep(1.6, 0.6, field.edge_m));

        // Trees: blobs with ragged edges, denser along field edges and in woodland, none by
        // the road.
        let density = 0.55 * trees_big + 0.45 * trees_small + kind.trees - 0.12
            + 0.18 * smoothstep(8.0, 1.0, field.edge_m)
            + Vec3A::new(0.0, 0.08, 0.05).dot(n.crown - 0.5)
            - smoothstep(9.0, 6.5, road_d);
        if density > 0.555 {
            c *= 1.0 - 0.3 * smoothstep(0.555, 0.58, density);
            let tree = smoothstep(0.58, 0.6, density);
            let canopy = Vec3A::new(0.5, 0.3, 0.2).dot(n.crown) + 0.1 * n.grain;
            let leaves = TREE_DARK.lerp(TREE_LIGHT, smoothstep(0.25, 0.75, canopy));
            c = c.lerp(leaves, tree);
        }
        c
    }
}

impl Imagery for SyntheticRouteImagery<'_> {
    fn project(&self, lat_deg: f64, lon_deg: f64) -> DVec2 {
        self.frame
            .geodetic_to_enu(&Geodetic::new(lat_deg, lon_deg, 0.0))
            .truncate()
    }

    fn sample(&mut self, p: DVec2) -> Result<Result<[u8; 3], Gap>, BuildError> {
        // Clamped, then rounded by adding 2^23: the integer lands in the low mantissa bits.
        let c = self.colour(p).clamp(Vec3A::ZERO, Vec3A::splat(255.0)) + 8_388_608.0;
        Ok(Ok(c.to_array().map(|v| v.to_bits() as u8)))
    }

    fn gap_error(&self, _gap: &Gap, lat_deg: f64, lon_deg: f64) -> BuildError {
        BuildError::Option(format!(
            "the synthetic route imagery has no gap, yet one was reported at {lat_deg}, {lon_deg}"
        ))
    }
}
