//! Writing images: OpenEXR (linear, 32-bit float, every layer as a channel group in one
//! part: "R,G,B" for the combined image, "<layer>.R/G/B" for passes) and 8-bit sRGB PNG.

use crate::error::RenderError;
use crate::film::Image;
use exr::prelude::{
    AnyChannel, AnyChannels, AttributeValue, Encoding, FlatSamples, Layer, LayerAttributes, SmallVec, Text,
    WritableImage,
};
use std::path::Path;

fn channel_names(layer: &str, channels: usize, first: bool) -> Vec<String> {
    let suffix: &[&str] = match channels {
        1 => &["V"],
        3 => &["R", "G", "B"],
        4 => &["R", "G", "B", "A"],
        _ => &["X", "Y", "Z", "W"],
    };
    suffix.iter().take(channels).map(|s| if first { s.to_string() } else { format!("{layer}.{s}") }).collect()
}

/// Writes named images of equal size into one EXR file. The first image is the main RGB.
pub fn write_exr(path: &Path, layers: &[(&str, &Image)]) -> Result<(), RenderError> {
    write_exr_with(path, layers, &[])
}

/// `write_exr` with text attributes in the file's header (`metadata`: name, value), e.g.
/// what rendered the image and whether the render was interrupted.
pub fn write_exr_with(path: &Path, layers: &[(&str, &Image)], metadata: &[(&str, &str)]) -> Result<(), RenderError> {
    let Some((_, first)) = layers.first() else {
        return Err(RenderError::Output("no image to write".into()));
    };
    let (w, h) = (first.width, first.height);
    if w == 0 || h == 0 {
        return Err(RenderError::Output("image has zero size".into()));
    }
    let mut list: Vec<AnyChannel<FlatSamples>> = Vec::new();
    for (k, (name, img)) in layers.iter().enumerate() {
        if img.width != w || img.height != h {
            return Err(RenderError::Output(format!(
                "layer '{name}' is {}×{}, expected {w}×{h}",
                img.width, img.height
            )));
        }
        for (c, cname) in channel_names(name, img.channels, k == 0).into_iter().enumerate() {
            let samples: Vec<f32> = img.data.iter().skip(c).step_by(img.channels).copied().collect();
            list.push(AnyChannel::new(cname.as_str(), FlatSamples::F32(samples)));
        }
    }
    let mut attributes = LayerAttributes::default();
    for (k, v) in metadata {
        let (Some(k), Some(v)) = (Text::new_or_none(*k), Text::new_or_none(*v)) else {
            return Err(RenderError::Output(format!("metadata '{k}' is not storable EXR text")));
        };
        attributes.other.insert(k, AttributeValue::Text(v));
    }
    let layer = Layer::new((w, h), attributes, Encoding::SMALL_LOSSLESS, AnyChannels::sort(SmallVec::from_vec(list)));
    exr::prelude::Image::from_layer(layer)
        .write()
        .to_file(path)
        .map_err(|e| RenderError::Output(format!("{}: {e}", path.display())))
}

/// sRGB opto-electronic transfer function (IEC 61966-2-1).
#[inline]
pub fn linear_to_srgb(x: f32) -> f32 {
    let x = if x.is_finite() { x.clamp(0.0, 1.0) } else { 0.0 };
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// Writes an RGB image as an 8-bit sRGB PNG (values clipped to [0, 1], like Blender's
/// "Standard" view transform).
/// The tEXt chunk every PNG GDMLT writes carries (keyword, text).
pub const PNG_SOFTWARE: (&str, &str) = ("Software", "GDMLT");

pub fn write_png(path: &Path, img: &Image) -> Result<(), RenderError> {
    if img.channels < 3 || img.width == 0 || img.height == 0 {
        return Err(RenderError::Output("PNG needs a non-empty RGB image".into()));
    }
    let err = |e: &dyn std::fmt::Display| RenderError::Output(format!("{}: {e}", path.display()));
    let file = std::fs::File::create(path).map_err(|e| err(&e))?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), img.width as u32, img.height as u32);
    let rgba = img.channels >= 4;
    enc.set_color(if rgba { png::ColorType::Rgba } else { png::ColorType::Rgb });
    enc.set_depth(png::BitDepth::Eight);
    enc.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
    // marks the file as GDMLT's: the CLI replaces a PNG beside its EXR only if it carries this
    enc.add_text_chunk(PNG_SOFTWARE.0.into(), PNG_SOFTWARE.1.into()).map_err(|e| err(&e))?;
    let mut writer = enc.write_header().map_err(|e| err(&e))?;
    let byte = |v: f32| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    let bytes: Vec<u8> = if rgba {
        // PNG alpha is straight: the premultiplied colour is divided by alpha first (as
        // Blender does when it saves a transparent film as PNG)
        img.data
            .chunks(img.channels)
            .flat_map(|px| {
                let a = if px[3].is_finite() { px[3].clamp(0.0, 1.0) } else { 1.0 };
                let k = if a > 0.0 { 1.0 / a } else { 0.0 };
                [
                    byte(linear_to_srgb(px[0] * k)),
                    byte(linear_to_srgb(px[1] * k)),
                    byte(linear_to_srgb(px[2] * k)),
                    byte(a),
                ]
            })
            .collect()
    } else {
        img.data.chunks(img.channels).flat_map(|px| (0..3).map(move |c| byte(linear_to_srgb(px[c])))).collect()
    };
    writer.write_image_data(&bytes).map_err(|e| err(&e))?;
    writer.finish().map_err(|e| err(&e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use exr::prelude::read_all_flat_layers_from_file;

    #[test]
    fn exr_round_trip_is_bit_exact() {
        let mut a = Image::new(5, 3, 3);
        for (i, v) in a.data.iter_mut().enumerate() {
            *v = i as f32 * 0.37 - 1.0;
        }
        let mut b = Image::new(5, 3, 3);
        b.data.iter_mut().enumerate().for_each(|(i, v)| *v = (i as f32).sqrt());
        let dir = std::env::temp_dir().join(format!("gdmlt-exr-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("t.exr");
        write_exr(&p, &[("Combined", &a), ("GD Primal", &b)]).unwrap();
        let img = read_all_flat_layers_from_file(&p).unwrap();
        let layer = &img.layer_data[0];
        let find = |name: &str| -> Vec<f32> {
            let ch = layer.channel_data.list.iter().find(|c| c.name.eq(name)).unwrap();
            ch.sample_data.values_as_f32().collect()
        };
        let r = find("R");
        let pr = find("GD Primal.G");
        for i in 0..15 {
            assert_eq!(r[i].to_bits(), a.data[i * 3].to_bits());
            assert_eq!(pr[i].to_bits(), b.data[i * 3 + 1].to_bits());
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn srgb_endpoints() {
        assert_eq!(linear_to_srgb(0.0), 0.0);
        assert!((linear_to_srgb(1.0) - 1.0).abs() < 1e-6);
        assert!((linear_to_srgb(0.18) - 0.4614).abs() < 1e-3);
        assert_eq!(linear_to_srgb(f32::NAN), 0.0);
    }
}
