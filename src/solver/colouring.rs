//! Deterministic greedy graph colouring for parallel Gauss-Seidel (STYLE: constraints of one
//! colour touch disjoint vertices). Constraints are taken in index order and each gets the
//! smallest colour none of its vertices has yet, so the result depends only on the input.

/// Colours `constraints` (each a list of vertex indices below `vertex_count`). Returns
/// `(order, offsets)`: constraint indices grouped by colour, colour c being
/// `order[offsets[c]..offsets[c + 1]]`, ascending within a colour.
pub fn colour_constraints<const N: usize>(constraints: &[[u32; N]], vertex_count: usize) -> (Vec<u32>, Vec<usize>) {
    // Colours used at each vertex, 64 per word; a vertex with more than 64·k colours around it
    // grows its words (rare: the colour count is about the largest vertex degree).
    let mut words = 1usize;
    let mut used = vec![0u64; vertex_count];
    let mut colour_of = Vec::with_capacity(constraints.len());
    let mut colour_count = 0usize;
    for c in constraints {
        let mut colour = None;
        for w in 0..words {
            let mut taken = 0u64;
            for &v in c {
                taken |= used[v as usize * words + w];
            }
            if taken != u64::MAX {
                colour = Some(w * 64 + (!taken).trailing_zeros() as usize);
                break;
            }
        }
        let colour = match colour {
            Some(colour) => colour,
            None => {
                // Every colour of every word is taken: widen the table by one word.
                let old = words;
                words += 1;
                let mut wider = vec![0u64; vertex_count * words];
                for v in 0..vertex_count {
                    wider[v * words..v * words + old].copy_from_slice(&used[v * old..v * old + old]);
                }
                used = wider;
                old * 64
            }
        };
        for &v in c {
            used[v as usize * words + colour / 64] |= 1u64 << (colour % 64);
        }
        colour_count = colour_count.max(colour + 1);
        colour_of.push(colour as u32);
    }
    let mut offsets = vec![0usize; colour_count + 1];
    for &c in &colour_of {
        offsets[c as usize + 1] += 1;
    }
    for c in 0..colour_count {
        offsets[c + 1] += offsets[c];
    }
    let mut next = offsets.clone();
    let mut order = vec![0u32; constraints.len()];
    for (i, &c) in colour_of.iter().enumerate() {
        order[next[c as usize]] = i as u32;
        next[c as usize] += 1;
    }
    (order, offsets)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours_are_independent_sets_and_cover_everything() {
        // A fan of 100 triangles around vertex 0 needs 100 colours (more than one word).
        let mut tris: Vec<[u32; 3]> = (0..100).map(|i| [0, i + 1, i + 2]).collect();
        tris.extend((0..50).map(|i| [200 + i, 201 + i, 202 + i]));
        let (order, offsets) = colour_constraints(&tris, 300);
        assert_eq!(order.len(), tris.len());
        let mut seen = vec![false; tris.len()];
        for c in 0..offsets.len() - 1 {
            let mut touched = std::collections::HashSet::new();
            for &i in &order[offsets[c]..offsets[c + 1]] {
                assert!(!seen[i as usize]);
                seen[i as usize] = true;
                for v in tris[i as usize] {
                    assert!(touched.insert(v), "colour {c} touches vertex {v} twice");
                }
            }
        }
        assert!(seen.iter().all(|&s| s));
        assert!(offsets.len() > 100);
        assert_eq!(colour_constraints(&tris, 300), (order, offsets));
    }
}
