//! What a written header says beyond the pixels: the views it may list,
//! and its attributes in a stable order, rewritten in place once the file
//! is written (for the writer, `merge` and `--part`).

/// Rewrite a finished file's headers (every part's) with their attributes
/// sorted by name. exr writes custom attributes in hash-map order, which
/// changes from run to run: without this, two runs of the same command give
/// files whose pixels are identical but whose bytes are not. The attributes
/// keep their bytes and each header its length (the spec allows any order),
/// so the offset tables after them stay right.
pub(crate) fn sort_header_attributes(
    file: &std::fs::File,
    replace: Option<(&str, &str)>,
) -> std::io::Result<()> {
    use std::io::{Read, Seek, SeekFrom, Write};
    let bad = |why: &str| std::io::Error::new(std::io::ErrorKind::InvalidData, why.to_string());
    let mut f = file;
    f.seek(SeekFrom::Start(0))?;
    // Headers are small; a bounded read keeps this cheap whatever the image.
    let mut buf = Vec::new();
    f.take(1 << 20).read_to_end(&mut buf)?;
    if buf.len() < 9 || buf[..4] != [0x76, 0x2f, 0x31, 0x01] {
        return Err(bad("not an OpenEXR file"));
    }
    let flags = u32::from_le_bytes([buf[4], buf[5], buf[6], buf[7]]);
    if flags & 0x800 != 0 {
        return Ok(()); // deep: not what epfilt writes
    }
    let multi = flags & 0x1000 != 0;
    let cstr_end = |from: usize| buf[from..].iter().position(|&b| b == 0).map(|p| from + p);
    // Each header: where it starts and its attributes.
    let mut headers: Vec<(usize, Vec<&[u8]>)> = Vec::new();
    let mut at = 8;
    loop {
        let start = at;
        let mut attrs: Vec<&[u8]> = Vec::new();
        loop {
            let name_end = cstr_end(at).ok_or_else(|| bad("header runs past 1 MiB"))?;
            if name_end == at {
                at += 1;
                break; // the empty name ends the header
            }
            let type_end = cstr_end(name_end + 1).ok_or_else(|| bad("truncated attribute type"))?;
            let size_at = type_end + 1;
            let size = buf
                .get(size_at..size_at + 4)
                .map(|b| i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .ok_or_else(|| bad("truncated attribute size"))?;
            let end = usize::try_from(size)
                .ok()
                .and_then(|n| (size_at + 4).checked_add(n))
                .filter(|&e| e <= buf.len())
                .ok_or_else(|| bad("attribute size out of range"))?;
            attrs.push(&buf[at..end]);
            at = end;
        }
        headers.push((start, attrs));
        // A multi-part file's headers end with an empty one.
        if !multi || buf.get(at).is_none_or(|&b| b == 0) {
            break;
        }
    }
    fn name(a: &[u8]) -> &[u8] {
        a.iter().position(|&b| b == 0).map_or(a, |p| &a[..p])
    }
    let mut replace = replace;
    let mut writes: Vec<(usize, Vec<u8>)> = Vec::new();
    for (start, attrs) in &headers {
        let mut sorted: Vec<Vec<u8>> = attrs.iter().map(|a| a.to_vec()).collect();
        sorted.sort_by(|a, b| name(a).cmp(name(b)));
        // A text attribute's value replaced by one of the same length (what
        // was not known when the header was written), in the first header
        // that has it.
        if let Some((key, value)) = replace {
            if let Some(a) = sorted.iter_mut().find(|a| name(a) == key.as_bytes()) {
                if a.len() < value.len() + key.len() + 4 {
                    return Err(bad("the attribute to fill is too short"));
                }
                let from = a.len() - value.len();
                a[from..].copy_from_slice(value.as_bytes());
                replace = None;
            }
        }
        if !sorted.iter().map(Vec::as_slice).eq(attrs.iter().copied()) {
            writes.push((*start, sorted.concat()));
        }
    }
    if replace.is_some() {
        return Err(bad("the attribute to fill is missing"));
    }
    for (start, bytes) in writes {
        f.seek(SeekFrom::Start(start as u64))?;
        f.write_all(&bytes)?;
    }
    f.flush()
}

/// The views of a `multiView` list that still have channels among `channels`
/// (OpenEXR's convention: a channel's view is its name's second-to-last
/// component when that is a listed view, else the first, default view).
/// The file must not name views whose channels were not written.
pub fn views_with_channels(views: &[String], channels: &[String]) -> Vec<String> {
    let view_of = |name: &str| -> usize {
        let parts: Vec<&str> = name.split('.').collect();
        if parts.len() >= 2 {
            if let Some(i) = views.iter().position(|v| v == parts[parts.len() - 2]) {
                return i;
            }
        }
        0
    };
    let mut used = vec![false; views.len()];
    for c in channels {
        if !views.is_empty() {
            used[view_of(c)] = true;
        }
    }
    views
        .iter()
        .zip(used)
        .filter(|(_, u)| *u)
        .map(|(v, _)| v.clone())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn views_without_channels_leave_the_multiview_list() {
        let views = names(&["left", "right"]);
        // The default (first) view's channels carry no view name.
        assert_eq!(
            views_with_channels(&views, &names(&["R", "G", "B"])),
            names(&["left"])
        );
        assert_eq!(
            views_with_channels(&views, &names(&["right.R", "right.G"])),
            names(&["right"])
        );
        assert_eq!(
            views_with_channels(&views, &names(&["R", "right.R", "diffuse.right.G"])),
            views
        );
        // A layer named like no view belongs to the default view.
        assert_eq!(
            views_with_channels(&views, &names(&["diffuse.R"])),
            names(&["left"])
        );
        assert!(views_with_channels(&views, &[]).is_empty());
        assert!(views_with_channels(&[], &names(&["R"])).is_empty());
    }
}
