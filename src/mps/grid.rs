//! Cell-list neighbour search in O(N) with a fixed neighbour order.
use super::particles::Vector;
use rayon::prelude::*;
use std::borrow::Cow;

/// Particles per parallel work item when building lists: a constant, so the split (and the
/// resulting order) never depends on the thread count.
const LIST_CHUNK: usize = 512;

/// The same for cutting lists to a radius: smaller, since the work is uneven (only fluid and
/// nearby walls have lists, often in a short range of indices).
const FILTER_CHUNK: usize = 64;

/// Bits of a list entry above this hold the symmetry planes its particle is reflected
/// across (bit a: the plane normal to axis a); the bits below, the particle's index.
const MIRROR_SHIFT: u32 = 29;
const INDEX_MASK: u32 = (1 << MIRROR_SHIFT) - 1;

/// The most particles a list can index (the top bits of an entry name mirror images).
pub const MAX_PARTICLES: usize = INDEX_MASK as usize;

/// The particle a list entry refers to (a mirror image refers to its source).
#[inline]
pub fn entry_index(e: u32) -> usize {
    (e & INDEX_MASK) as usize
}

/// Mirror symmetry planes x_a = position_m[a] for the axes a set in `axes` (bit a): the
/// domain lies on the side x_a >= position_m[a], and every particle within reach of a plane
/// has a mirror image beyond it that the lists hold as an entry of its own (same index,
/// plane bits set): a scalar field reads the source's value, a vector field the source's
/// value with the plane's normal component negated, a displacement the reflected position.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MirrorPlanes {
    pub axes: u32,
    pub position_m: [f64; 3],
}

impl MirrorPlanes {
    pub fn is_empty(&self) -> bool {
        self.axes == 0
    }

    /// The axes whose bit is set in `planes` (an entry's plane bits, or `axes`).
    pub fn axes_of<const D: usize>(planes: u32) -> impl Iterator<Item = usize> {
        (0..D).filter(move |a| planes >> a & 1 == 1)
    }

    /// Every non-empty combination of the planes, as plane bits in ascending order: the
    /// images a point can have (none without planes).
    pub fn combinations(&self) -> impl Iterator<Item = u32> + use<> {
        let axes = self.axes;
        (1..=axes).filter(move |planes| planes & axes == *planes)
    }

    /// Whether `x` lies on the domain's side of every plane (strictly).
    pub fn beside<const D: usize>(&self, x: &Vector<D>) -> bool {
        Self::axes_of::<D>(self.axes).all(|a| x[a] > self.position_m[a])
    }

    /// `x` reflected across the planes in `planes`.
    #[inline]
    pub fn reflect_point<const D: usize>(&self, planes: u32, mut x: Vector<D>) -> Vector<D> {
        for a in Self::axes_of::<D>(planes) {
            x[a] = 2.0 * self.position_m[a] - x[a];
        }
        x
    }
}

/// Neighbour lists in rows: the neighbours of i are `indices[offsets[i]..ends[i]]`, in
/// ascending index order (then mirror images, see [`MirrorPlanes`], by plane bits and then by
/// index). Rows follow one another in index order; built lists are compressed (`ends[i] ==
/// offsets[i + 1]`), while the kernel-pair cut ([`KernelPairs`]) leaves each row where its
/// candidates were, with unused entries between rows, so that no serial pass has to move
/// them together (`offsets[n]` is then the extent of the rows). Entries are read with
/// [`entry_index`], [`Neighbours::displacement`] and [`Neighbours::reflect`].
#[derive(Debug, Clone, Default)]
pub struct Neighbours {
    pub cutoff_m: f64,
    /// Period of a periodic x axis (minimum-image displacements), if any.
    pub period_x_m: Option<f64>,
    pub mirror: MirrorPlanes,
    pub offsets: Vec<usize>,
    pub ends: Vec<usize>,
    pub indices: Vec<u32>,
}

impl Neighbours {
    #[inline]
    pub fn of(&self, i: usize) -> &[u32] {
        &self.indices[self.offsets[i]..self.ends[i]]
    }

    /// Compressed rows from their offsets (row i ends where row i + 1 starts).
    fn compressed(
        cutoff_m: f64,
        period_x_m: Option<f64>,
        mirror: MirrorPlanes,
        offsets: Vec<usize>,
        indices: Vec<u32>,
    ) -> Self {
        let ends = offsets[1..].to_vec();
        Self {
            cutoff_m,
            period_x_m,
            mirror,
            offsets,
            ends,
            indices,
        }
    }

    /// r_ij = r_j - r_i for list entry `e` of i: the nearest periodic image along x when x is
    /// periodic, the reflected position for a mirror image.
    #[inline]
    pub fn displacement<const D: usize>(
        &self,
        positions: &[Vector<D>],
        i: usize,
        e: u32,
    ) -> Vector<D> {
        let j = entry_index(e);
        let mut r = positions[j] - positions[i];
        let planes = e >> MIRROR_SHIFT;
        if planes != 0 {
            r = self.mirror.reflect_point(planes, positions[j]) - positions[i];
        }
        if let Some(period) = self.period_x_m {
            r[0] -= period * (r[0] / period).round();
        }
        r
    }

    /// A vector value of entry `e`'s particle as its mirror image carries it: the planes'
    /// normal components negated (unchanged for a plain entry).
    #[inline]
    pub fn reflect<const D: usize>(&self, e: u32, v: Vector<D>) -> Vector<D> {
        Self::reflected(e, v)
    }

    /// As [`Neighbours::reflect`], for `e` an entry or a column index that carries its plane
    /// bits ([`Neighbours::plane_bits`]).
    #[inline]
    pub fn reflected<const D: usize>(e: u32, mut v: Vector<D>) -> Vector<D> {
        // A plain entry returns at once: this is read for every pair of the hot loops.
        let planes = e >> MIRROR_SHIFT;
        if planes != 0 {
            for a in MirrorPlanes::axes_of::<D>(planes) {
                v[a] = -v[a];
            }
        }
        v
    }

    /// -1 when entry `e` is a mirror image across the plane normal to `axis`, else 1: the
    /// sign with which it carries component `axis` of a vector field.
    #[inline]
    pub fn component_sign(e: u32, axis: usize) -> f64 {
        if (e >> MIRROR_SHIFT) >> axis & 1 == 1 {
            -1.0
        } else {
            1.0
        }
    }

    /// The plane bits of entry `e` in place (0 for a plain entry), to ride along a matrix
    /// column index of the viscous matrix (`CsrMatrix::component_diagonal`).
    #[inline]
    pub fn plane_bits(e: u32) -> u32 {
        e & !INDEX_MASK
    }

    /// Whether entry `e` is i's own mirror image.
    #[inline]
    pub fn is_own_image(e: u32, i: usize) -> bool {
        e >> MIRROR_SHIFT != 0 && entry_index(e) == i
    }

    /// All j != i with |r_j - r_i| < cutoff_m, for every particle.
    pub fn build<const D: usize>(positions: &[Vector<D>], cutoff_m: f64) -> Self {
        Self::build_general(positions, cutoff_m, None, &|_| true, &|_| true)
    }

    /// As [`Neighbours::build`] for the particles with `active(i)`: only those with
    /// `centre(i)` too get a list of their own; the other active ones are neighbours only
    /// (dummy wall layers: no operator is ever evaluated at them).
    pub fn build_centres<const D: usize>(
        positions: &[Vector<D>],
        cutoff_m: f64,
        active: impl Fn(usize) -> bool + Sync,
        centre: impl Fn(usize) -> bool + Sync,
    ) -> Self {
        Self::build_general(positions, cutoff_m, None, &active, &centre)
    }

    /// The pairs of these lists closer than `outer_m` and those closer than `inner_m <=
    /// outer_m` (and not coincident), in the same order, for particles with `keep(i)` (the
    /// others get empty lists; one distance per pair): exactly the pairs with a nonzero weight
    /// w(r) for each radius. Operators that skip zero-weight pairs give the same bits on the
    /// cut lists, and visit far fewer pairs (in 3D the number-density radius holds a quarter
    /// of the Verlet list).
    pub fn within_two<const D: usize>(
        &self,
        positions: &[Vector<D>],
        outer_m: f64,
        inner_m: f64,
        keep: impl Fn(usize) -> bool + Sync,
    ) -> (Self, Self) {
        self.within_two_by(
            positions,
            outer_m,
            inner_m,
            |i| if keep(i) { Cut::Always } else { Cut::Never },
            |_| false,
            (Self::default(), Self::default()),
        )
    }

    /// As [`Neighbours::within_two`], each particle cut as `cut(i)` says; a
    /// [`Cut::IfFluidWithin`] particle keeps its pairs only when one of them within `outer_m`
    /// is fluid (`is_fluid`). `reuse` lends the storage of earlier cuts (outer, inner).
    fn within_two_by<const D: usize>(
        &self,
        positions: &[Vector<D>],
        outer_m: f64,
        inner_m: f64,
        cut: impl Fn(usize) -> Cut + Sync,
        is_fluid: impl Fn(usize) -> bool + Sync,
        reuse: (Self, Self),
    ) -> (Self, Self) {
        debug_assert!(inner_m <= outer_m);
        let (outer2, inner2) = (sqrt_threshold(outer_m), sqrt_threshold(inner_m));
        let n = self.offsets.len() - 1;
        // Each row's pairs are written where the row lies in `self` (room for every
        // candidate, without a branch per pair: about a third fail, in no predictable
        // pattern), in parallel over fixed chunks of rows, and stay there: the rows keep
        // the gaps between them (see `Neighbours`).
        let total = self.offsets[n];
        let (mut outer, mut inner) = reuse;
        for lists in [&mut outer, &mut inner] {
            // Grown, never shrunk: what lies past the rows is never read.
            if lists.indices.len() < total {
                lists.indices.resize(total, 0);
            }
            lists.offsets.resize(n + 1, 0);
            lists.offsets[n] = total;
            lists.ends.resize(n, 0);
        }
        let chunk_rows = |chunk: usize| chunk * FILTER_CHUNK..((chunk + 1) * FILTER_CHUNK).min(n);
        let chunks = n.div_ceil(FILTER_CHUNK);
        let mut regions = Vec::with_capacity(chunks);
        let (mut rest_outer, mut rest_inner) =
            (&mut outer.indices[..total], &mut inner.indices[..total]);
        for chunk in 0..chunks {
            let rows = chunk_rows(chunk);
            let room = self.offsets[rows.end] - self.offsets[rows.start];
            let (o, tail_o) = std::mem::take(&mut rest_outer).split_at_mut(room);
            let (i, tail_i) = std::mem::take(&mut rest_inner).split_at_mut(room);
            (rest_outer, rest_inner) = (tail_o, tail_i);
            regions.push((rows, o, i));
        }
        regions
            .into_par_iter()
            .zip(outer.offsets[..n].par_chunks_mut(FILTER_CHUNK))
            .zip(outer.ends.par_chunks_mut(FILTER_CHUNK))
            .zip(inner.offsets[..n].par_chunks_mut(FILTER_CHUNK))
            .zip(inner.ends.par_chunks_mut(FILTER_CHUNK))
            .with_max_len(1)
            .for_each(
                |(
                    ((((rows, outer, inner), starts_outer), ends_outer), starts_inner),
                    ends_inner,
                )| {
                    let base = self.offsets[rows.start];
                    let (mut len_outer, mut len_inner) = (0, 0);
                    for (k, i) in rows.enumerate() {
                        let before = (len_outer, len_inner);
                        let how = cut(i);
                        if how != Cut::Never {
                            let row = self.of(i);
                            // Without a period, the plain entries (mirror images come last,
                            // see `Neighbours`) are cut in a loop of their own.
                            debug_assert!(row.is_sorted(), "row {i} out of order");
                            let plain = if self.period_x_m.is_none() {
                                row.partition_point(|&e| e >> MIRROR_SHIFT == 0)
                            } else {
                                0
                            };
                            let (o, n_in) = cut_plain_row(
                                &row[..plain],
                                positions[i],
                                positions,
                                (outer2, inner2),
                                &mut outer[len_outer..len_outer + plain],
                                &mut inner[len_inner..len_inner + plain],
                            );
                            len_outer += o;
                            len_inner += n_in;
                            for &j in &row[plain..] {
                                let d2 = self.displacement(positions, i, j).norm_squared();
                                outer[len_outer] = j;
                                inner[len_inner] = j;
                                len_outer += usize::from(d2 > 0.0 && d2 < outer2);
                                len_inner += usize::from(d2 > 0.0 && d2 < inner2);
                            }
                            // The kept pairs within the outer radius name any fluid there
                            // (from the end: poured fluid comes last).
                            if how == Cut::IfFluidWithin
                                && !outer[before.0..len_outer]
                                    .iter()
                                    .rev()
                                    .any(|&j| is_fluid(entry_index(j)))
                            {
                                (len_outer, len_inner) = before;
                            }
                        }
                        (starts_outer[k], ends_outer[k]) = (base + before.0, base + len_outer);
                        (starts_inner[k], ends_inner[k]) = (base + before.1, base + len_inner);
                    }
                },
            );
        for (lists, cutoff_m) in [(&mut outer, outer_m), (&mut inner, inner_m)] {
            lists.cutoff_m = cutoff_m;
            lists.period_x_m = self.period_x_m;
            lists.mirror = self.mirror;
        }
        (outer, inner)
    }

    /// Marks every particle that is in some list, over `n` particles.
    pub fn listed(&self, n: usize) -> Vec<bool> {
        let mut mark = vec![false; n];
        for i in 0..self.ends.len() {
            for &j in self.of(i) {
                mark[entry_index(j)] = true;
            }
        }
        mark
    }

    /// Row by row, the list of `self` where it is not empty, else the list of `other` (for
    /// lists built for disjoint sets of particles).
    pub fn merged(&self, other: &Self) -> Self {
        let n = self.offsets.len() - 1;
        assert_eq!(n, other.offsets.len() - 1);
        let mut offsets = Vec::with_capacity(n + 1);
        offsets.push(0);
        let mut indices = Vec::with_capacity(self.indices.len() + other.indices.len());
        for i in 0..n {
            let own = self.of(i);
            indices.extend_from_slice(if own.is_empty() { other.of(i) } else { own });
            offsets.push(indices.len());
        }
        Self::compressed(
            self.cutoff_m,
            self.period_x_m,
            self.mirror,
            offsets,
            indices,
        )
    }

    /// Lists of `rows` rows, row k's entries appended by `row(k, list)`, in parallel over
    /// fixed chunks of rows (so the split never depends on the thread count).
    fn by_rows(
        rows: usize,
        cutoff_m: f64,
        period_x_m: Option<f64>,
        mirror: MirrorPlanes,
        row: impl Fn(usize, &mut Vec<u32>) + Sync,
    ) -> Self {
        let chunks: Vec<(Vec<usize>, Vec<u32>)> = (0..rows.div_ceil(LIST_CHUNK))
            .into_par_iter()
            .with_max_len(1)
            .map(|chunk| {
                let range = chunk * LIST_CHUNK..((chunk + 1) * LIST_CHUNK).min(rows);
                let mut counts = Vec::with_capacity(range.len());
                let mut list = Vec::with_capacity(range.len() * 32);
                for k in range {
                    let before = list.len();
                    row(k, &mut list);
                    counts.push(list.len() - before);
                }
                (counts, list)
            })
            .collect();
        Self::from_chunks(cutoff_m, period_x_m, mirror, chunks)
    }

    fn from_chunks(
        cutoff_m: f64,
        period_x_m: Option<f64>,
        mirror: MirrorPlanes,
        chunks: Vec<(Vec<usize>, Vec<u32>)>,
    ) -> Self {
        let mut offsets = Vec::with_capacity(chunks.iter().map(|c| c.0.len()).sum::<usize>() + 1);
        offsets.push(0);
        let mut indices = Vec::with_capacity(chunks.iter().map(|c| c.1.len()).sum());
        for (counts, list) in chunks {
            for c in counts {
                offsets.push(offsets.last().unwrap() + c);
            }
            indices.extend_from_slice(&list);
        }
        Self::compressed(cutoff_m, period_x_m, mirror, offsets, indices)
    }

    /// As [`Neighbours::build`] with x periodic of period `period_x_m` (all particles must lie
    /// within one period; the period must be at least three cutoffs).
    pub fn build_periodic_x<const D: usize>(
        positions: &[Vector<D>],
        cutoff_m: f64,
        period_x_m: f64,
    ) -> Self {
        assert!(
            period_x_m >= 3.0 * cutoff_m,
            "period {period_x_m} shorter than three cutoffs"
        );
        Self::build_general(positions, cutoff_m, Some(period_x_m), &|_| true, &|_| true)
    }

    /// Lists for the particles with `centre(i)`, then for those with `then(i)` that the
    /// first lists hold, merged row by row (walls near the fluid: one cell grid for both).
    /// With `mirror` planes, the lists also hold the mirror images of the active particles
    /// closer than the cutoff to a plane (images are never centres).
    pub fn build_centres_then_listed<const D: usize>(
        positions: &[Vector<D>],
        cutoff_m: f64,
        period_x_m: Option<f64>,
        mirror: MirrorPlanes,
        active: impl Fn(usize) -> bool + Sync,
        centre: impl Fn(usize) -> bool + Sync,
        then: impl Fn(usize) -> bool + Sync,
    ) -> Self {
        let n = positions.len();
        assert!(
            n <= MAX_PARTICLES,
            "{n} particles, more than {MAX_PARTICLES}"
        );
        if mirror.is_empty() {
            let grid = CellGrid::new(positions, cutoff_m, period_x_m);
            let first = grid.lists(positions, &active, &centre);
            let listed = first.listed(n);
            let second = grid.lists(positions, &active, &|i: usize| listed[i] && then(i));
            return first.merged(&second);
        }
        let (extended, images) = Self::with_images(positions, cutoff_m, mirror, &active);
        let active = |k: usize| k >= n || active(k);
        let grid = CellGrid::new(&extended, cutoff_m, period_x_m);
        let first = grid.lists(&extended, &active, &|k: usize| k < n && centre(k));
        let listed = first.listed(extended.len());
        let second = grid.lists(&extended, &active, &|k: usize| {
            k < n && listed[k] && then(k)
        });
        let mut lists = first.merged(&second);
        // Images have no lists of their own (they are last); their entries name the source.
        lists.offsets.truncate(n + 1);
        lists.ends.truncate(n);
        for e in &mut lists.indices {
            if *e as usize >= n {
                *e = images[*e as usize - n];
            }
        }
        lists.mirror = mirror;
        lists
    }

    /// The points the lists with mirror planes are searched among: the particles, then the
    /// mirror images of the active ones closer than the cutoff to the planes, in a fixed order
    /// (plane bits, then index), so that a list's order does not depend on which images
    /// existed when it was built. The second vector names each image as a list entry (its
    /// source's index with its plane bits), ascending.
    fn with_images<'a, const D: usize>(
        positions: &'a [Vector<D>],
        cutoff_m: f64,
        mirror: MirrorPlanes,
        active: &impl Fn(usize) -> bool,
    ) -> (Cow<'a, [Vector<D>]>, Vec<u32>) {
        if mirror.is_empty() {
            return (Cow::Borrowed(positions), Vec::new());
        }
        let mut extended = positions.to_vec();
        let mut images: Vec<u32> = Vec::new();
        for planes in mirror.combinations() {
            for (j, x) in positions.iter().enumerate() {
                let near = MirrorPlanes::axes_of::<D>(planes)
                    .all(|a| x[a] - mirror.position_m[a] < cutoff_m);
                if near && active(j) {
                    extended.push(mirror.reflect_point(planes, *x));
                    images.push(j as u32 | planes << MIRROR_SHIFT);
                }
            }
        }
        assert!(
            extended.len() <= MAX_PARTICLES,
            "too many particles with mirror images"
        );
        (Cow::Owned(extended), images)
    }

    /// The lists that [`Neighbours::build_centres_then_listed`] gives at `positions` (with
    /// `self`'s period and mirror planes), from `self`, these lists at positions that differ
    /// only at the particles `moved` (ascending and active; every particle past `self`'s
    /// count among them; no particle's `active`, `centre` or `then` changed). Only the moved
    /// particles (and their mirror images) are searched in the cell grid; every other list is
    /// `self`'s, the moved entries taken out and their new ones merged in, so the cost follows
    /// the moved particles, not all of them.
    pub fn updated<const D: usize>(
        &self,
        positions: &[Vector<D>],
        moved: &[u32],
        active: impl Fn(usize) -> bool + Sync,
        centre: impl Fn(usize) -> bool + Sync,
        then: impl Fn(usize) -> bool + Sync,
    ) -> Self {
        let n = positions.len();
        let listed_before = self.offsets.len() - 1;
        debug_assert!(moved.windows(2).all(|w| w[0] < w[1]));
        assert!(
            (listed_before..n).all(|i| moved.binary_search(&(i as u32)).is_ok()),
            "every particle past the lists must be among the moved"
        );
        // Row of each moved particle in `moved` (NOT_MOVED for the others).
        const NOT_MOVED: u32 = u32::MAX;
        let mut row_of = vec![NOT_MOVED; n];
        for (k, &s) in moved.iter().enumerate() {
            row_of[s as usize] = k as u32;
        }
        let is_moved = |e: u32| row_of[entry_index(e)] != NOT_MOVED;
        // The points searched: the particles, then the images (none without planes), as the
        // whole build has them; a point's entry is its index, or its image's name.
        let (extended, images) = Self::with_images(positions, self.cutoff_m, self.mirror, &active);
        let active_point = |k: usize| k >= n || active(k);
        let entry_of = |k: u32| {
            if (k as usize) < n {
                k
            } else {
                images[k as usize - n]
            }
        };
        let grid = CellGrid::new(&extended, self.cutoff_m, self.period_x_m);
        // The entries within the cutoff of the points `subset` (row k: point subset[k]),
        // ascending: the images keep the order of their points.
        let searched = |subset: &[u32]| {
            Self::by_rows(
                subset.len(),
                self.cutoff_m,
                self.period_x_m,
                self.mirror,
                |k, list| {
                    let before = list.len();
                    grid.append_neighbours(&extended, subset[k] as usize, &active_point, list);
                    for e in &mut list[before..] {
                        *e = entry_of(*e);
                    }
                },
            )
        };
        // Every moved particle's neighbours, holder or not: they are also where the moved
        // particle enters the others' lists (the cut is symmetric).
        let moved_lists = searched(moved);
        // A moved particle's image enters the lists of the particles within the cutoff of
        // the image: searched from the image's point, one plane combination at a time
        // (row k: the k-th image, named by its entry, ascending).
        let mut image_rows: Vec<(Vec<u32>, Neighbours)> = Vec::new();
        for planes in self.mirror.combinations() {
            let (entries, points): (Vec<u32>, Vec<u32>) = moved
                .iter()
                .filter_map(|&s| {
                    let e = s | planes << MIRROR_SHIFT;
                    images.binary_search(&e).ok().map(|k| (e, (n + k) as u32))
                })
                .unzip();
            let rows = searched(&points);
            image_rows.push((entries, rows));
        }
        // The entries of moved particles (and their images) each particle gains, ascending:
        // the plain ones first (moved is ascending), then by plane bits.
        let plain = |e: &u32| *e >> MIRROR_SHIFT == 0;
        // (the entries searched from, their lists): row k of a list is searched from entry k.
        let searches: Vec<(&[u32], &Neighbours)> = std::iter::once((moved, &moved_lists))
            .chain(
                image_rows
                    .iter()
                    .map(|(entries, rows)| (&entries[..], rows)),
            )
            .collect();
        let mut gained_offsets = vec![0usize; n + 1];
        for (_, list) in &searches {
            for &i in list.indices.iter().filter(|e| plain(e)) {
                gained_offsets[i as usize + 1] += 1;
            }
        }
        for i in 0..n {
            gained_offsets[i + 1] += gained_offsets[i];
        }
        let mut fill = gained_offsets.clone();
        let mut gained = vec![0u32; gained_offsets[n]];
        let mut gain = |row: &[u32], e: u32| {
            for &i in row.iter().filter(|e| plain(e)) {
                gained[fill[i as usize]] = e;
                fill[i as usize] += 1;
            }
        };
        for (sources, rows) in &searches {
            for (k, &e) in sources.iter().enumerate() {
                gain(rows.of(k), e);
            }
        }
        let gained_of = |i: usize| &gained[gained_offsets[i]..gained_offsets[i + 1]];
        // A particle holds a list for the centres whose own lists hold it, so only a centre's
        // plain entry counts (an image is never a centre).
        let is_centre = |e: u32| plain(&e) && active(e as usize) && centre(e as usize);
        // A `then` particle has a list when some centre lies within the cutoff: one that did
        // not move and was in its list, or a moved one that now is.
        let holds_list = |i: usize| {
            if !active(i) {
                return false;
            }
            if centre(i) {
                return true;
            }
            if !then(i) {
                return false;
            }
            if is_moved(i as u32) {
                return moved_lists
                    .of(row_of[i] as usize)
                    .iter()
                    .any(|&e| is_centre(e));
            }
            let kept = self.of(i).iter().any(|&e| !is_moved(e) && is_centre(e));
            kept || gained_of(i).iter().any(|&e| is_centre(e))
        };
        // Particles that did not move (so were listed before) and hold a list now but held
        // none: searched whole. A centre always held its (possibly empty) list.
        let new_holders: Vec<u32> = (0..n)
            .into_par_iter()
            .with_min_len(LIST_CHUNK)
            .filter(|&i| {
                !is_moved(i as u32) && !centre(i) && self.of(i).is_empty() && holds_list(i)
            })
            .map(|i| i as u32)
            .collect();
        let new_holder_lists = searched(&new_holders);
        Self::by_rows(n, self.cutoff_m, self.period_x_m, self.mirror, |i, list| {
            if !holds_list(i) {
                return;
            }
            if is_moved(i as u32) {
                list.extend_from_slice(moved_lists.of(row_of[i] as usize));
            } else if let Ok(k) = new_holders.binary_search(&(i as u32)) {
                list.extend_from_slice(new_holder_lists.of(k));
            } else {
                // Both ascending: merge the kept entries with the gained ones.
                let kept = self.of(i).iter().filter(|&&e| !is_moved(e));
                merge_ascending(kept.copied(), gained_of(i), list);
            }
        })
    }

    fn build_general<const D: usize>(
        positions: &[Vector<D>],
        cutoff_m: f64,
        period_x_m: Option<f64>,
        active: &(impl Fn(usize) -> bool + Sync),
        centre: &(impl Fn(usize) -> bool + Sync),
    ) -> Self {
        CellGrid::new(positions, cutoff_m, period_x_m).lists(positions, active, centre)
    }
}

/// Particles sorted into cells at least one cutoff wide (counting sort: ascending index
/// within a cell).
struct CellGrid<const D: usize> {
    cutoff_m: f64,
    period_x_m: Option<f64>,
    lo: Vector<D>,
    dims: [usize; D],
    width: [f64; D],
    /// The particles of flat cell c are `sorted[start[c]..start[c + 1]]`.
    start: Vec<usize>,
    sorted: Vec<u32>,
}

impl<const D: usize> CellGrid<D> {
    fn new(positions: &[Vector<D>], cutoff_m: f64, period_x_m: Option<f64>) -> Self {
        let mut lo = positions
            .first()
            .copied()
            .unwrap_or_else(Vector::<D>::zeros);
        let mut hi = lo;
        for p in positions {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        let mut dims = [1usize; D];
        let mut width = [cutoff_m; D];
        for a in 0..D {
            dims[a] = (((hi[a] - lo[a]) / cutoff_m).floor() as usize) + 1;
        }
        if let Some(period) = period_x_m {
            // Whole cells around the period, each at least one cutoff wide.
            dims[0] = (period / cutoff_m).floor() as usize;
            width[0] = period / dims[0] as f64;
        }
        let mut grid = Self {
            cutoff_m,
            period_x_m,
            lo,
            dims,
            width,
            start: Vec::new(),
            sorted: Vec::new(),
        };
        let cell_count: usize = dims.iter().product();
        let cells: Vec<usize> = positions
            .par_iter()
            .map(|p| grid.flat(&grid.cell_of(p)))
            .collect();
        let mut start = vec![0usize; cell_count + 1];
        for &c in &cells {
            start[c + 1] += 1;
        }
        for c in 0..cell_count {
            start[c + 1] += start[c];
        }
        let mut fill = start.clone();
        let mut sorted = vec![0u32; positions.len()];
        for (i, &c) in cells.iter().enumerate() {
            sorted[fill[c]] = i as u32;
            fill[c] += 1;
        }
        grid.start = start;
        grid.sorted = sorted;
        grid
    }

    fn cell_of(&self, p: &Vector<D>) -> [usize; D] {
        let mut c = [0usize; D];
        for a in 0..D {
            c[a] = (((p[a] - self.lo[a]) / self.width[a]).floor() as usize).min(self.dims[a] - 1);
        }
        c
    }

    fn flat(&self, c: &[usize; D]) -> usize {
        let mut f = 0;
        for a in (0..D).rev() {
            f = f * self.dims[a] + c[a];
        }
        f
    }

    /// All active j != i closer than the cutoff, for every i with `active(i) && centre(i)`.
    fn lists(
        &self,
        positions: &[Vector<D>],
        active: &(impl Fn(usize) -> bool + Sync),
        centre: &(impl Fn(usize) -> bool + Sync),
    ) -> Neighbours {
        Neighbours::by_rows(
            positions.len(),
            self.cutoff_m,
            self.period_x_m,
            MirrorPlanes::default(),
            |i, list| {
                if active(i) && centre(i) {
                    self.append_neighbours(positions, i, active, list);
                }
            },
        )
    }

    /// Appends to `list` every active j != i closer than the cutoff to particle i, in
    /// ascending index order: the order (hence every sum's rounding) then does not depend on
    /// where the cells were when the list was built.
    fn append_neighbours(
        &self,
        positions: &[Vector<D>],
        i: usize,
        active: &(impl Fn(usize) -> bool + Sync),
        list: &mut Vec<u32>,
    ) {
        let before = list.len();
        let cutoff2 = self.cutoff_m * self.cutoff_m;
        let image = Neighbours {
            cutoff_m: self.cutoff_m,
            period_x_m: self.period_x_m,
            mirror: MirrorPlanes::default(),
            offsets: Vec::new(),
            ends: Vec::new(),
            indices: Vec::new(),
        };
        let wrap = self.period_x_m.is_some();
        let (dims, start, sorted) = (&self.dims, &self.start, &self.sorted);
        let ci = self.cell_of(&positions[i]);
        // Visit the 3^D surrounding cells in a fixed (flat) order.
        for k in 0..3usize.pow(D as u32) {
            let mut rest = k;
            let mut c = [0usize; D];
            let mut inside = true;
            for a in 0..D {
                let off = (rest % 3) as i64 - 1;
                rest /= 3;
                let mut v = ci[a] as i64 + off;
                if a == 0 && wrap {
                    v = v.rem_euclid(dims[0] as i64);
                }
                if v < 0 || v >= dims[a] as i64 {
                    inside = false;
                    break;
                }
                c[a] = v as usize;
            }
            if !inside {
                continue;
            }
            let f = self.flat(&c);
            let cell = &sorted[start[f]..start[f + 1]];
            if wrap {
                for &j in cell {
                    if j as usize != i
                        && active(j as usize)
                        && image.displacement(positions, i, j).norm_squared() < cutoff2
                    {
                        list.push(j);
                    }
                }
            } else {
                each_within(cell, i, positions, cutoff2, |j| {
                    if active(j as usize) {
                        list.push(j);
                    }
                });
            }
        }
        list[before..].sort_unstable();
    }
}

/// Appends the union of two ascending sequences of distinct indices, ascending.
fn merge_ascending(a: impl Iterator<Item = u32>, b: &[u32], out: &mut Vec<u32>) {
    let mut b = b.iter().copied().peekable();
    for x in a {
        while let Some(y) = b.next_if(|&y| y < x) {
            out.push(y);
        }
        out.push(x);
    }
    out.extend(b);
}

/// Calls `found(j)`, in order, for each j of `candidates` (plain indices, no period) other
/// than `i` with |x_j - x_i|^2 < `cutoff2`. Eight at a time where the CPU has AVX-512
/// ([`wide::each_within`], the same calls), else one at a time.
fn each_within<const D: usize>(
    candidates: &[u32],
    i: usize,
    positions: &[Vector<D>],
    cutoff2: f64,
    mut found: impl FnMut(u32),
) {
    #[cfg(target_arch = "x86_64")]
    if wide_available() {
        // SAFETY: the features were detected just above.
        return unsafe { wide::each_within(candidates, i, positions, cutoff2, &mut found) };
    }
    each_within_scalar(candidates, i, positions, cutoff2, &mut found);
}

/// [`each_within`] one candidate at a time.
fn each_within_scalar<const D: usize>(
    candidates: &[u32],
    i: usize,
    positions: &[Vector<D>],
    cutoff2: f64,
    found: &mut impl FnMut(u32),
) {
    let x_i = positions[i];
    for &j in candidates {
        if j as usize != i && (positions[j as usize] - x_i).norm_squared() < cutoff2 {
            found(j);
        }
    }
}

/// The entries of `row` (plain indices, no images) closer to `x_i` than the two thresholds
/// on |r|^2 ([`sqrt_threshold`]; coincident points excluded), written in order to the fronts
/// of `outer` and `inner` (each as long as `row`): their counts. Eight entries at a time
/// where the CPU has AVX-512 ([`wide::cut_plain_row`], the same bits), else one at a time.
fn cut_plain_row<const D: usize>(
    row: &[u32],
    x_i: Vector<D>,
    positions: &[Vector<D>],
    thresholds: (f64, f64),
    outer: &mut [u32],
    inner: &mut [u32],
) -> (usize, usize) {
    #[cfg(target_arch = "x86_64")]
    if wide_available() {
        // SAFETY: the features were detected just above.
        return unsafe { wide::cut_plain_row(row, x_i, positions, thresholds, outer, inner) };
    }
    cut_plain_row_scalar(row, x_i, positions, thresholds, (0, 0), outer, inner)
}

/// [`cut_plain_row`] one entry at a time from `row`, counts starting at `(o, n_in)`. A loop
/// of its own, so that nothing else competes for its registers.
#[inline(never)]
fn cut_plain_row_scalar<const D: usize>(
    row: &[u32],
    x_i: Vector<D>,
    positions: &[Vector<D>],
    (outer2, inner2): (f64, f64),
    (mut o, mut n_in): (usize, usize),
    outer: &mut [u32],
    inner: &mut [u32],
) -> (usize, usize) {
    for &j in row {
        // r = x_j - x_i, as `Neighbours::displacement` gives it without images.
        let d2 = (positions[j as usize] - x_i).norm_squared();
        outer[o] = j;
        inner[n_in] = j;
        // `&`, not `&&`: no branch to mispredict.
        let apart = d2 > 0.0;
        o += usize::from(apart & (d2 < outer2));
        n_in += usize::from(apart & (d2 < inner2));
    }
    (o, n_in)
}

/// Whether this CPU runs the eight-wide loops ([`wide`]); detected once by std.
#[cfg(target_arch = "x86_64")]
fn wide_available() -> bool {
    std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512vl")
}

/// Eight neighbour candidates at a time under AVX-512 F and VL, for the two loops that
/// measure every candidate of a list or a cell: the list cut ([`cut_plain_row`]) and the
/// cell search ([`each_within`]). Each gives the scalar loop's result bit for bit: |r|^2
/// is formed as nalgebra's `norm_squared` forms it ((r0 r0 + r1 r1) + r2 r2, no fused
/// multiply-add), so every comparison is the scalar one. The scalar loops wait on one load
/// chain (index, then position) per candidate; the cut was a third of a 3D pour.
#[cfg(target_arch = "x86_64")]
mod wide {
    use super::Vector;
    use std::arch::x86_64::*;

    /// |x_j - x_i|^2 for the eight indices in `j`, `centre` holding x_i per component.
    /// Panics, as slice indexing would, when an index is past the positions.
    ///
    /// # Safety
    /// The CPU must have AVX-512 F and VL.
    #[inline]
    #[target_feature(enable = "avx512f,avx512vl")]
    pub(super) unsafe fn squared_distances<const D: usize>(
        j: __m256i,
        centre: &[__m512d; D],
        positions: &[Vector<D>],
    ) -> __m512d {
        // A position is D contiguous f64 (nalgebra's array storage), read at index times D.
        const { assert!(std::mem::size_of::<Vector<D>>() == D * std::mem::size_of::<f64>()) };
        // Indices are below MAX_PARTICLES (2^29), so u32 compares hold them.
        let count = u32::try_from(positions.len()).unwrap_or(u32::MAX);
        if _mm256_cmplt_epu32_mask(j, _mm256_set1_epi32(count as i32)) != 0xff {
            panic!(
                "index out of bounds: a neighbour past {} positions",
                positions.len()
            );
        }
        // Eight plain loads per component, not a gather: on AMD Zen 4 `vgatherqpd` is slower
        // than the loads and inserts it stands for (the 3D rock fill 0.92x, the 16 mm slump
        // 0.98x), and the values, hence the bits, are the same.
        let mut idx = [0u32; 8];
        // SAFETY: eight lanes into eight.
        unsafe { _mm256_storeu_si256(idx.as_mut_ptr().cast(), j) };
        let base = positions.as_ptr().cast::<f64>();
        let mut d2 = _mm512_setzero_pd();
        for (c, centre_c) in centre.iter().enumerate() {
            // SAFETY: every index is below `positions.len()` (checked above), so each offset
            // j D + c lies within the positions' D len() values.
            let at = |k: usize| unsafe { *base.add(idx[k] as usize * D + c) };
            let x = _mm512_set_pd(at(7), at(6), at(5), at(4), at(3), at(2), at(1), at(0));
            let r = _mm512_sub_pd(x, *centre_c);
            let rr = _mm512_mul_pd(r, r);
            d2 = if c == 0 { rr } else { _mm512_add_pd(d2, rr) };
        }
        d2
    }

    /// The indices of `j` that `keep` selects, in order, at `out[0..]`; all eight lanes are
    /// written, those past the kept ones with zeros. Compressed in a register and stored
    /// whole: a compress straight to memory (`vpcompressd m256`) is microcoded on AMD Zen 4.
    ///
    /// # Safety
    /// The CPU must have AVX-512 F and VL, and `out` must be valid for eight writes.
    #[inline]
    #[target_feature(enable = "avx512f,avx512vl")]
    unsafe fn store_kept(out: *mut u32, keep: __mmask8, j: __m256i) {
        // SAFETY: the caller's promise.
        unsafe { _mm256_storeu_si256(out.cast(), _mm256_maskz_compress_epi32(keep, j)) };
    }

    /// x_i per component, for [`squared_distances`].
    ///
    /// # Safety
    /// The CPU must have AVX-512 F.
    #[inline]
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn centre<const D: usize>(x_i: &Vector<D>) -> [__m512d; D] {
        std::array::from_fn(|c| _mm512_set1_pd(x_i[c]))
    }

    /// [`super::cut_plain_row`] eight entries at a time, the kept indices compressed into
    /// place in order; the last `row.len() % 8` through the scalar loop.
    ///
    /// # Safety
    /// The CPU must have AVX-512 F and VL.
    #[target_feature(enable = "avx512f,avx512vl")]
    pub(super) unsafe fn cut_plain_row<const D: usize>(
        row: &[u32],
        x_i: Vector<D>,
        positions: &[Vector<D>],
        (outer2, inner2): (f64, f64),
        outer: &mut [u32],
        inner: &mut [u32],
    ) -> (usize, usize) {
        assert!(outer.len() >= row.len() && inner.len() >= row.len());
        let (mut o, mut n_in) = (0usize, 0usize);
        let blocks = row.len() / 8;
        // SAFETY (both calls): the caller's CPU has the features.
        let centre = unsafe { centre(&x_i) };
        let (outer2_v, inner2_v, zero) = (
            _mm512_set1_pd(outer2),
            _mm512_set1_pd(inner2),
            _mm512_setzero_pd(),
        );
        for b in 0..blocks {
            // SAFETY: `b * 8 + 8 <= row.len()`.
            let j = unsafe { _mm256_loadu_si256(row.as_ptr().add(b * 8).cast()) };
            let d2 = unsafe { squared_distances(j, &centre, positions) };
            let apart = _mm512_cmp_pd_mask::<_CMP_GT_OQ>(d2, zero);
            let keep_outer = apart & _mm512_cmp_pd_mask::<_CMP_LT_OQ>(d2, outer2_v);
            let keep_inner = apart & _mm512_cmp_pd_mask::<_CMP_LT_OQ>(d2, inner2_v);
            // The lanes past the kept ones are overwritten by the next block or never read.
            // SAFETY: `o` and `n_in` are at most `b * 8`, so each eight-lane store ends within
            // the first `row.len()` of `outer` and `inner`.
            unsafe {
                store_kept(outer.as_mut_ptr().add(o), keep_outer, j);
                store_kept(inner.as_mut_ptr().add(n_in), keep_inner, j);
            }
            o += keep_outer.count_ones() as usize;
            n_in += keep_inner.count_ones() as usize;
        }
        super::cut_plain_row_scalar(
            &row[blocks * 8..],
            x_i,
            positions,
            (outer2, inner2),
            (o, n_in),
            outer,
            inner,
        )
    }

    /// [`super::each_within`] eight candidates at a time; the last `candidates.len() % 8`
    /// through the scalar loop.
    ///
    /// # Safety
    /// The CPU must have AVX-512 F and VL.
    #[target_feature(enable = "avx512f,avx512vl")]
    pub(super) unsafe fn each_within<const D: usize>(
        candidates: &[u32],
        i: usize,
        positions: &[Vector<D>],
        cutoff2: f64,
        found: &mut impl FnMut(u32),
    ) {
        let blocks = candidates.len() / 8;
        // SAFETY (both calls): the caller's CPU has the features.
        let centre = unsafe { centre(&positions[i]) };
        let (cutoff2_v, own) = (_mm512_set1_pd(cutoff2), _mm256_set1_epi32(i as i32));
        let mut kept = [0u32; 8];
        for b in 0..blocks {
            // SAFETY: `b * 8 + 8 <= candidates.len()`.
            let j = unsafe { _mm256_loadu_si256(candidates.as_ptr().add(b * 8).cast()) };
            let d2 = unsafe { squared_distances(j, &centre, positions) };
            let keep =
                _mm512_cmp_pd_mask::<_CMP_LT_OQ>(d2, cutoff2_v) & _mm256_cmpneq_epu32_mask(j, own);
            if keep != 0 {
                // SAFETY: eight lanes into eight.
                unsafe { store_kept(kept.as_mut_ptr(), keep, j) };
                kept[..keep.count_ones() as usize]
                    .iter()
                    .for_each(|&j| found(j));
            }
        }
        super::each_within_scalar(&candidates[blocks * 8..], i, positions, cutoff2, found);
    }
}

/// Which pairs of a particle's list [`Neighbours::within_two_by`] keeps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Cut {
    Never,
    Always,
    /// Only when a fluid particle is within the outer radius.
    IfFluidWithin,
}

/// The smallest t with sqrt(t) >= radius_m: for d2 >= 0, sqrt(d2) < radius_m exactly when
/// d2 < t (sqrt is correctly rounded, hence monotone), so a cut on |r|^2 keeps the same pairs
/// as a cut on |r| = sqrt(|r|^2) without a square root per pair.
pub fn sqrt_threshold(radius_m: f64) -> f64 {
    let mut t = radius_m * radius_m;
    while t.sqrt() < radius_m {
        t = t.next_up();
    }
    while t.next_down().sqrt() >= radius_m {
        t = t.next_down();
    }
    t
}

/// The pairs of the (Verlet) lists that carry weight at the current positions, one list per
/// kernel radius: `near` within the number-density/gradient radius, `lap` within the Laplacian
/// radius. Same order as the lists they come from.
#[derive(Debug, Clone, Default)]
pub struct KernelPairs {
    pub near: Neighbours,
    pub lap: Neighbours,
}

impl KernelPairs {
    /// Pairs at every particle.
    pub fn new<const D: usize>(
        lists: &Neighbours,
        positions: &[Vector<D>],
        radius_n_m: f64,
        radius_lap_m: f64,
    ) -> Self {
        let (lap, near) =
            lists.within_two(positions, radius_lap_m.max(radius_n_m), radius_n_m, |_| {
                true
            });
        Self { near, lap }
    }

    /// Pairs at the fluid particles and at the other particles within the Laplacian radius of
    /// some fluid particle (at these positions, so independent of when `lists` were built);
    /// other particles get none. One pass: a wall particle's own list holds every fluid
    /// particle whose list holds it (lists are symmetric among their centres, and a wall
    /// near no fluid at the last build has no list and no fluid within reach now).
    /// `reuse` lends the storage of an earlier cut (none allocated when it is large enough).
    pub fn near_fluid<const D: usize>(
        lists: &Neighbours,
        positions: &[Vector<D>],
        radius_n_m: f64,
        radius_lap_m: f64,
        is_fluid: impl Fn(usize) -> bool + Sync,
        reuse: Self,
    ) -> Self {
        let radius = radius_lap_m.max(radius_n_m);
        let (lap, near) = lists.within_two_by(
            positions,
            radius,
            radius_n_m,
            |i| {
                if is_fluid(i) {
                    Cut::Always
                } else {
                    Cut::IfFluidWithin
                }
            },
            &is_fluid,
            (reuse.lap, reuse.near),
        );
        Self { near, lap }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Kinds drawn at random: 0 fluid (`fluid_tenths` in ten), 1 wall (up to eight in ten),
    /// 2 dummy (one in ten), 3 ghost (the rest).
    fn random_kinds(rng: &mut crate::rng::SplitMix64, n: usize, fluid_tenths: u8) -> Vec<u8> {
        (0..n)
            .map(|_| match (rng.unit() * 10.0) as u8 {
                d if d < fluid_tenths => 0,
                0..=7 => 1,
                8 => 2,
                _ => 3,
            })
            .collect()
    }

    /// An update equals the whole build at the new positions, entry for entry, in 2D and 3D,
    /// periodic or not, with mirror planes or not: fluid moved (some far, into walls' reach
    /// and out of it, towards a plane and away from it), walls moved, particles appended, a
    /// ghost that never gets a list.
    fn check_update_equals_build<const D: usize>(
        period_x_m: Option<f64>,
        mirror: MirrorPlanes,
        seed: u64,
    ) {
        let mut rng = crate::rng::SplitMix64::new(seed);
        // A few neighbours each, so that some walls have no fluid in reach.
        let (n0, added) = (900usize, 40usize);
        let cutoff_m = if D == 2 { 0.025 } else { 0.05 };
        let side_m = 0.6;
        let mut kinds = random_kinds(&mut rng, n0, 5);
        let point =
            |rng: &mut crate::rng::SplitMix64| Vector::<D>::from_fn(|_, _| side_m * rng.unit());
        let before: Vec<Vector<D>> = (0..n0).map(|_| point(&mut rng)).collect();
        kinds.extend(std::iter::repeat_n(0, added));
        let mut after = before.clone();
        after.extend((0..added).map(|_| point(&mut rng)));
        let mut moved: Vec<u32> = Vec::new();
        for i in 0..n0 + added {
            // Half the particles within two cutoffs of a plane move, and a third of the moved
            // ones go next to a plane: images appear, vanish and move.
            let near_plane = |x: &Vector<D>| {
                MirrorPlanes::axes_of::<D>(mirror.axes)
                    .any(|a| x[a] - mirror.position_m[a] < 2.0 * cutoff_m)
            };
            let far = i < n0 && (rng.unit() < 0.1 || (near_plane(&before[i]) && rng.unit() < 0.5));
            if (i >= n0 || far) && kinds[i] != 3 {
                if i < n0 {
                    // Up to two cutoffs in any direction, kept inside the box.
                    let step = Vector::<D>::from_fn(|_, _| (rng.unit() - 0.5) * 4.0 * cutoff_m);
                    after[i] = (after[i] + step).map(|x| x.clamp(0.0, side_m * 0.999));
                    if let Some(a) = MirrorPlanes::axes_of::<D>(mirror.axes).next()
                        && rng.unit() < 1.0 / 3.0
                    {
                        after[i][a] = mirror.position_m[a].max(0.0) + cutoff_m * rng.unit();
                    }
                }
                moved.push(i as u32);
            }
        }
        let k = &kinds;
        let build = |x: &[Vector<D>]| {
            Neighbours::build_centres_then_listed(
                x,
                cutoff_m,
                period_x_m,
                mirror,
                |i| k[i] != 3,
                |i| k[i] == 0,
                |i| k[i] == 1,
            )
        };
        // The lists before know only the first n0 particles.
        let old = build(&before);
        let updated = old.updated(&after, &moved, |i| k[i] != 3, |i| k[i] == 0, |i| k[i] == 1);
        let whole = build(&after);
        assert_eq!(updated.offsets, whole.offsets);
        assert_eq!(updated.indices, whole.indices);
        // The moves changed some lists (the check is not vacuous) and walls gained and lost lists.
        assert_ne!(old.indices, whole.indices[..]);
        let holders = |l: &Neighbours, n: usize| {
            (0..n)
                .filter(|&i| !l.of(i).is_empty() && k[i] == 1)
                .collect::<Vec<_>>()
        };
        assert_ne!(holders(&old, n0), holders(&whole, n0));
        // With planes, moved particles' images entered and left lists.
        if !mirror.is_empty() {
            let images_of_moved = |l: &Neighbours| {
                l.indices
                    .iter()
                    .filter(|&&e| {
                        e >> MIRROR_SHIFT != 0 && moved.contains(&(entry_index(e) as u32))
                    })
                    .count()
            };
            assert!(images_of_moved(&whole) > 0);
            assert!(images_of_moved(&old) > 0);
        }
    }

    #[test]
    fn an_update_equals_the_whole_build() {
        let none = MirrorPlanes::default();
        // A plane through the points' lowest x (where they may touch it), and one in y beside it.
        let x = MirrorPlanes {
            axes: 0b1,
            position_m: [0.0; 3],
        };
        let xy = MirrorPlanes {
            axes: 0b11,
            position_m: [0.0, -0.01, 0.0],
        };
        for seed in 1..4 {
            for mirror in [none, x, xy] {
                check_update_equals_build::<2>(None, mirror, seed);
                check_update_equals_build::<3>(None, mirror, seed);
            }
            check_update_equals_build::<2>(Some(0.6), none, seed);
            check_update_equals_build::<3>(Some(0.6), none, seed);
            // A period along x beside a plane normal to y.
            let y = MirrorPlanes { axes: 0b10, ..xy };
            check_update_equals_build::<2>(Some(0.6), y, seed);
            check_update_equals_build::<3>(Some(0.6), y, seed);
        }
    }

    /// The kernel-pair cut keeps, row by row and in order, exactly the entries within each
    /// radius (by `displacement`, the general path), walls only with fluid within the outer
    /// one; the same with storage lent by a cut of other lists. 2D and 3D, plain, periodic and
    /// with a mirror plane.
    fn check_cut_equals_the_definition<const D: usize>(
        period_x_m: Option<f64>,
        mirror: MirrorPlanes,
        seed: u64,
    ) {
        let mut rng = crate::rng::SplitMix64::new(seed);
        let n = 1200usize;
        let (cutoff_m, side_m) = (if D == 2 { 0.03 } else { 0.06 }, 0.6);
        let (outer_m, inner_m) = (0.8 * cutoff_m, 0.5 * cutoff_m);
        let mut kinds = random_kinds(&mut rng, n, 4);
        let mut listed: Vec<Vector<D>> = (0..n)
            .map(|_| Vector::<D>::from_fn(|_, _| side_m * (0.001 + 0.998 * rng.unit())))
            .collect();
        // Two fluid particles that meet.
        (kinds[0], kinds[1]) = (0, 0);
        listed[1] = listed[0] + Vector::<D>::from_element(0.1 * cutoff_m);
        // Moved within a tenth of the cutoff since the lists were made; one pair coincident.
        let mut now: Vec<Vector<D>> = listed
            .iter()
            .map(|x| x + Vector::<D>::from_fn(|_, _| (rng.unit() - 0.5) * 0.1 * cutoff_m))
            .map(|x| x.map(|c| c.clamp(0.0005, side_m - 0.0005)))
            .collect();
        now[1] = now[0];
        let k = &kinds;
        let lists = Neighbours::build_centres_then_listed(
            &listed,
            cutoff_m,
            period_x_m,
            mirror,
            |i| k[i] != 3,
            |i| k[i] == 0,
            |i| k[i] == 1,
        );
        let is_fluid = |i: usize| k[i] == 0;
        let fresh = KernelPairs::near_fluid(
            &lists,
            &now,
            inner_m,
            outer_m,
            is_fluid,
            KernelPairs::default(),
        );
        // Storage lent by a cut of longer lists, its contents stale.
        let longer = Neighbours::build_centres_then_listed(
            &listed,
            1.5 * cutoff_m,
            period_x_m,
            mirror,
            |i| k[i] != 3,
            |i| k[i] == 0,
            |i| k[i] == 1,
        );
        let lent = KernelPairs::near_fluid(
            &longer,
            &now,
            inner_m,
            outer_m,
            is_fluid,
            KernelPairs::default(),
        );
        let reused = KernelPairs::near_fluid(&lists, &now, inner_m, outer_m, is_fluid, lent);
        let within = |i: usize, radius_m: f64| -> Vec<u32> {
            let t = sqrt_threshold(radius_m);
            lists
                .of(i)
                .iter()
                .copied()
                .filter(|&e| {
                    let d2 = lists.displacement(&now, i, e).norm_squared();
                    d2 > 0.0 && d2 < t
                })
                .collect()
        };
        let (mut walls_kept, mut walls_dropped) = (0, 0);
        for (i, &kind) in kinds.iter().enumerate() {
            let outer = within(i, outer_m);
            let keep = is_fluid(i) || outer.iter().any(|&e| is_fluid(entry_index(e)));
            if kind == 1 && !lists.of(i).is_empty() {
                if keep {
                    walls_kept += 1;
                } else {
                    walls_dropped += 1;
                }
            }
            let (outer, inner) = if keep {
                (outer, within(i, inner_m))
            } else {
                (Vec::new(), Vec::new())
            };
            for pairs in [&fresh, &reused] {
                assert_eq!(pairs.lap.of(i), outer, "outer pairs of {i}");
                assert_eq!(pairs.near.of(i), inner, "inner pairs of {i}");
            }
        }
        assert!(
            walls_kept > 0 && walls_dropped > 0,
            "{walls_kept} {walls_dropped}"
        );
        // Each radius cut some entries, and the coincident pair is not one.
        let entries = |l: &Neighbours| (0..l.ends.len()).map(|i| l.of(i).len()).sum::<usize>();
        assert!(entries(&fresh.near) < entries(&fresh.lap));
        assert!(entries(&fresh.lap) < entries(&lists));
        assert!(lists.of(0).contains(&1) && !fresh.lap.of(0).contains(&1));
        if !mirror.is_empty() {
            assert!((0..n).any(|i| fresh.lap.of(i).iter().any(|&e| e >> MIRROR_SHIFT != 0)));
        }
    }

    #[test]
    fn the_cut_keeps_exactly_the_pairs_within_each_radius() {
        let plane = MirrorPlanes {
            axes: 1,
            position_m: [0.0; 3],
        };
        for seed in 1..3 {
            for (period, mirror) in [
                (None, MirrorPlanes::default()),
                (Some(0.6), MirrorPlanes::default()),
                (None, plane),
            ] {
                check_cut_equals_the_definition::<2>(period, mirror, seed);
                check_cut_equals_the_definition::<3>(period, mirror, seed);
            }
        }
    }

    /// `n` points in a 0.1 m box, every `every`-th one on point 0 (coincident pairs).
    fn points_with_twins<const D: usize>(
        rng: &mut crate::rng::SplitMix64,
        n: usize,
        every: usize,
    ) -> Vec<Vector<D>> {
        let mut positions: Vec<Vector<D>> = (0..n)
            .map(|_| Vector::<D>::from_fn(|_, _| 0.1 * rng.unit()))
            .collect();
        for k in (0..n).step_by(every) {
            positions[k] = positions[0];
        }
        positions
    }

    /// One row's cut by [`cut_plain_row`] (eight at a time where the CPU has AVX-512) and by
    /// the scalar loop: the same counts and the same kept entries, in order, on rows of every
    /// length from 0 to 40 (whole blocks and tails), with coincident points and with each
    /// threshold equal to some pair's |r|^2 (so that `<` against `<=` shows).
    fn check_wide_cut_equals_scalar<const D: usize>(seed: u64) {
        let mut rng = crate::rng::SplitMix64::new(seed);
        let n = 400;
        let positions = points_with_twins::<D>(&mut rng, n, 37);
        for len in 0..=40 {
            let i = (rng.unit() * n as f64) as usize;
            let mut row: Vec<u32> = (0..len).map(|_| (rng.unit() * n as f64) as u32).collect();
            row.sort_unstable();
            row.dedup();
            let d2_of = |k: usize| (positions[row[k] as usize] - positions[i]).norm_squared();
            let (outer2, inner2) = if row.is_empty() {
                (1.0, 0.5)
            } else {
                let (a, b) = (d2_of(row.len() / 2), d2_of(row.len() / 3));
                (a.max(b), a.min(b))
            };
            let mut wide = (vec![u32::MAX; row.len()], vec![u32::MAX; row.len()]);
            let mut plain = (vec![u32::MAX; row.len()], vec![u32::MAX; row.len()]);
            let (o, m) = cut_plain_row(
                &row,
                positions[i],
                &positions,
                (outer2, inner2),
                &mut wide.0,
                &mut wide.1,
            );
            let (o_s, m_s) = cut_plain_row_scalar(
                &row,
                positions[i],
                &positions,
                (outer2, inner2),
                (0, 0),
                &mut plain.0,
                &mut plain.1,
            );
            assert_eq!((o, m), (o_s, m_s), "{D}D row of {len}");
            assert_eq!(wide.0[..o], plain.0[..o], "{D}D row of {len}");
            assert_eq!(wide.1[..m], plain.1[..m], "{D}D row of {len}");
        }
    }

    /// The cell search's candidates by [`each_within`] and by the scalar loop: the same
    /// calls in the same order, the own index left out, a cutoff tied to a pair's |r|^2.
    fn check_wide_search_equals_scalar<const D: usize>(seed: u64) {
        let mut rng = crate::rng::SplitMix64::new(seed);
        let n = 300;
        let positions = points_with_twins::<D>(&mut rng, n, 29);
        for len in 0..=40 {
            let i = (rng.unit() * n as f64) as usize;
            // Cell order is not index order: candidates unsorted, the own index among them.
            let mut cell: Vec<u32> = (0..len).map(|_| (rng.unit() * n as f64) as u32).collect();
            if len > 3 {
                cell[len / 2] = i as u32;
            }
            let cutoff2 = cell.get(len / 3).map_or(1.0, |&j| {
                (positions[j as usize] - positions[i]).norm_squared()
            });
            let (mut wide, mut plain) = (Vec::new(), Vec::new());
            each_within(&cell, i, &positions, cutoff2, |j| wide.push(j));
            each_within_scalar(&cell, i, &positions, cutoff2, &mut |j| plain.push(j));
            assert_eq!(wide, plain, "{D}D cell of {len}");
            assert!(!plain.contains(&(i as u32)));
        }
    }

    #[test]
    fn the_wide_cell_search_finds_the_scalar_loops_neighbours() {
        for seed in 1..6 {
            check_wide_search_equals_scalar::<2>(seed);
            check_wide_search_equals_scalar::<3>(seed);
        }
    }

    #[test]
    fn the_wide_cut_keeps_the_pairs_of_the_scalar_loop() {
        for seed in 1..6 {
            check_wide_cut_equals_scalar::<2>(seed);
            check_wide_cut_equals_scalar::<3>(seed);
        }
    }

    /// An index past the positions is refused in the eight-wide loop as by slice indexing.
    #[test]
    #[should_panic(expected = "index out of bounds")]
    fn the_wide_cut_refuses_an_index_past_the_positions() {
        let positions = vec![Vector::<3>::zeros(); 10];
        let row: Vec<u32> = (0..16).map(|k| if k == 5 { 10 } else { k }).collect();
        let (mut outer, mut inner) = (vec![0; 16], vec![0; 16]);
        cut_plain_row(
            &row,
            positions[0],
            &positions,
            (1.0, 0.5),
            &mut outer,
            &mut inner,
        );
    }

    /// The squared cut keeps exactly the distances the square-root cut keeps, at the edge too.
    #[test]
    fn squared_cut_equals_distance_cut() {
        for k in 1..2000 {
            let radius = 0.001 * k as f64 * 3.1;
            let t = sqrt_threshold(radius);
            assert!(t.sqrt() >= radius && t.next_down().sqrt() < radius);
            let mut d2 = t;
            for _ in 0..8 {
                d2 = d2.next_down();
            }
            for _ in 0..16 {
                assert_eq!(d2 < t, d2.sqrt() < radius, "radius {radius}, d2 {d2}");
                d2 = d2.next_up();
            }
        }
    }
}
