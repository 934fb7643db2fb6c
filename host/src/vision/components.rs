//! Connected components of a binary mask (8-connected) and the outer boundary of one
//! component (radial-sweep border following, clockwise on screen): the contour step of the
//! ArUco detector and the labelling step of the blob detector.

/// One connected component of the mask.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Component {
    /// Pixels in the component.
    pub area: usize,
    /// Bounding box, inclusive: `(min_x, min_y, max_x, max_y)`.
    pub bbox: (usize, usize, usize, usize),
    /// The first pixel in raster order (topmost, then leftmost), `(x, y)`.
    pub start: (usize, usize),
}

impl Component {
    /// Bounding-box width and height.
    pub fn size(&self) -> (usize, usize) {
        (self.bbox.2 - self.bbox.0 + 1, self.bbox.3 - self.bbox.1 + 1)
    }
}

/// A labelled mask: `label(x, y) = k + 1` for component `k`, 0 for background.
#[derive(Clone, Debug)]
pub struct Labels {
    width: usize,
    height: usize,
    labels: Vec<u32>,
    /// The components, in raster order of their first pixel.
    pub components: Vec<Component>,
}

/// The 8 neighbour offsets, clockwise on screen (y down) from east.
const DIRS: [(isize, isize); 8] = [
    (1, 0),
    (1, 1),
    (0, 1),
    (-1, 1),
    (-1, 0),
    (-1, -1),
    (0, -1),
    (1, -1),
];

impl Labels {
    /// Labels the `true` pixels of a row-major `width x height` mask, 8-connected.
    /// A mask of the wrong length gives no components.
    pub fn new(mask: &[bool], width: usize, height: usize) -> Self {
        let mut out = Self {
            width,
            height,
            labels: vec![0; width * height],
            components: Vec::new(),
        };
        if mask.len() != width * height {
            return out;
        }
        let mut stack = Vec::new();
        for start in 0..mask.len() {
            if !mask[start] || out.labels[start] != 0 {
                continue;
            }
            let label = out.components.len() as u32 + 1;
            let (sx, sy) = (start % width, start / width);
            let mut comp = Component {
                area: 0,
                bbox: (sx, sy, sx, sy),
                start: (sx, sy),
            };
            out.labels[start] = label;
            stack.push(start);
            while let Some(i) = stack.pop() {
                let (x, y) = (i % width, i / width);
                comp.area += 1;
                comp.bbox = (
                    comp.bbox.0.min(x),
                    comp.bbox.1.min(y),
                    comp.bbox.2.max(x),
                    comp.bbox.3.max(y),
                );
                for (dx, dy) in DIRS {
                    let (nx, ny) = (x as isize + dx, y as isize + dy);
                    if nx < 0 || ny < 0 || nx >= width as isize || ny >= height as isize {
                        continue;
                    }
                    let j = ny as usize * width + nx as usize;
                    if mask[j] && out.labels[j] == 0 {
                        out.labels[j] = label;
                        stack.push(j);
                    }
                }
            }
            out.components.push(comp);
        }
        out
    }

    /// The label at `(x, y)` (0 background or outside).
    pub fn label(&self, x: isize, y: isize) -> u32 {
        if x < 0 || y < 0 || x >= self.width as isize || y >= self.height as isize {
            return 0;
        }
        self.labels[y as usize * self.width + x as usize]
    }

    /// The pixels of component `k`, `(x, y)`, in raster order (scans its bounding box).
    pub fn pixels(&self, k: usize) -> Vec<(usize, usize)> {
        let Some(c) = self.components.get(k) else {
            return Vec::new();
        };
        let label = k as u32 + 1;
        let mut out = Vec::with_capacity(c.area);
        for y in c.bbox.1..=c.bbox.3 {
            for x in c.bbox.0..=c.bbox.2 {
                if self.labels[y * self.width + x] == label {
                    out.push((x, y));
                }
            }
        }
        out
    }

    /// The outer boundary of component `k`: its border pixels `(x, y)` in order, clockwise
    /// on screen, starting at its first pixel; each pixel once per visit (a one-pixel-wide
    /// spur is walked out and back).
    pub fn outer_boundary(&self, k: usize) -> Vec<(i32, i32)> {
        let Some(c) = self.components.get(k) else {
            return Vec::new();
        };
        let label = k as u32 + 1;
        let start = (c.start.0 as isize, c.start.1 as isize);
        let next = |p: (isize, isize), came: usize| -> Option<(usize, (isize, isize))> {
            // Sweep clockwise from the neighbour after the one we came from.
            (1..=8).map(|s| (came + s) % 8).find_map(|d| {
                let q = (p.0 + DIRS[d].0, p.1 + DIRS[d].1);
                (self.label(q.0, q.1) == label).then_some((d, q))
            })
        };
        // At the first pixel, W, NW, N and NE are background: start the sweep at W.
        let Some((first_dir, second)) = next(start, 3) else {
            return vec![(start.0 as i32, start.1 as i32)];
        };
        let mut contour = vec![(start.0 as i32, start.1 as i32)];
        let (mut p, mut d) = (second, first_dir);
        let limit = 4 * c.area + 8;
        while contour.len() < limit {
            let Some((nd, q)) = next(p, (d + 4) % 8) else {
                break;
            };
            if p == start && q == second {
                break;
            }
            contour.push((p.0 as i32, p.1 as i32));
            (p, d) = (q, nd);
        }
        contour
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mask_of(rows: &[&str]) -> (Vec<bool>, usize, usize) {
        let w = rows[0].len();
        let m = rows
            .iter()
            .flat_map(|r| r.chars().map(|c| c == '#'))
            .collect();
        (m, w, rows.len())
    }

    #[test]
    fn labels_two_components_and_traces_a_square_ring_clockwise() {
        let (m, w, h) = mask_of(&[
            "......#", //
            ".####..", //
            ".#..#..", //
            ".####..", //
            ".......",
        ]);
        let labels = Labels::new(&m, w, h);
        assert_eq!(labels.components.len(), 2);
        assert_eq!(labels.components[0].area, 1);
        let ring = labels.components[1];
        assert_eq!(
            (ring.area, ring.bbox, ring.start),
            (10, (1, 1, 4, 3), (1, 1))
        );
        let b = labels.outer_boundary(1);
        assert_eq!(
            b,
            vec![
                (1, 1),
                (2, 1),
                (3, 1),
                (4, 1),
                (4, 2),
                (4, 3),
                (3, 3),
                (2, 3),
                (1, 3),
                (1, 2)
            ]
        );
        assert_eq!(labels.outer_boundary(0), vec![(6, 0)]);
    }

    #[test]
    fn traces_the_outside_of_a_filled_diamond() {
        let (m, w, h) = mask_of(&[
            "...#...", //
            "..###..", //
            ".#####.", //
            "..###..", //
            "...#...",
        ]);
        let labels = Labels::new(&m, w, h);
        let b = labels.outer_boundary(0);
        assert_eq!(
            b,
            vec![
                (3, 0),
                (4, 1),
                (5, 2),
                (4, 3),
                (3, 4),
                (2, 3),
                (1, 2),
                (2, 1)
            ]
        );
    }
}
