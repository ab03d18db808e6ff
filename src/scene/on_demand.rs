//! Images that do not all live in memory: a view whose image is decoded again from its file
//! each time it is needed, through a cache bounded in bytes and shared by the views of a scene.
//!
//! [`super::load`] keeps every image in memory while all of them fit in
//! [`super::LoadOptions::image_memory`] bytes (2 GiB by default). When the images of a scene
//! would need more, every view becomes an [`OnDemandImage`]: the loader still decodes each image
//! once (to check it and to build its camera, mask and coverage) but keeps, instead of its
//! pixels, what it needs to decode it again and a 64-bit fingerprint of the pixels it produced
//! (FNV-1a of the processed 8-bit image, [`crate::fnv`]). A later decode that gives other pixels
//! (the file was edited or replaced since the scene was loaded) is an error naming the file,
//! [`SceneError::ImageChanged`], never a different image trained on in silence. A decode that
//! gives the same pixels gives exactly the image the in-memory path holds: training on an
//! on-demand scene is bit-identical to training on the same scene in memory.
//!
//! The cache holds the decoded 8-bit images, at most `image_memory` bytes of them; the least
//! recently used image leaves first. An image handed out ([`OnDemandImage::load`]) is shared,
//! so a caller still holding one after it left the cache holds it a little longer: the bound
//! is `image_memory` plus the images in use (one per step or evaluation thread).
//!
//! The cache also keeps the storage of [`SPARE_BUFFERS`] images that left it, for the next
//! decodes, so that images leaving and arriving do not scatter the heap.
//!
//! Masks and alpha coverage (one byte a pixel each, [`super::View::mask`],
//! [`super::View::coverage`]) stay in memory.
//!
//! ```
//! use bbsplat::scene::Image;
//! use bbsplat::scene::on_demand::ImageCache;
//! use std::sync::Arc;
//! let cache = ImageCache::new(12); // bytes: two 2×1 images (6 bytes each)
//! let image = |v: u8| Arc::new(Image::new(2, 1, vec![v; 6]).unwrap());
//! cache.insert(0, image(1));
//! cache.insert(1, image(2));
//! assert!(cache.get(0).is_some()); // 0 is now the most recently used
//! cache.insert(2, image(3)); // 1 leaves
//! assert!(cache.get(1).is_none());
//! assert_eq!(cache.stats().held_bytes, 12);
//! ```

use super::error::SceneError;
use super::views::{ViewSource, load_view};
use super::{Image, LoadOptions};
use std::collections::HashMap;
use std::fmt;
use std::path::Path;
use std::sync::{Arc, Mutex, MutexGuard};

/// The default of [`super::LoadOptions::image_memory`]: 2 GiB.
pub const DEFAULT_IMAGE_MEMORY: u64 = 2 << 30;

/// What an [`ImageCache`] did so far.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CacheStats {
    /// Lookups that found their image.
    pub hits: u64,
    /// Lookups that did not (the image was then decoded).
    pub misses: u64,
    /// Bytes of the images held now.
    pub held_bytes: u64,
    /// The most bytes held at once.
    pub peak_bytes: u64,
}

/// Decoded 8-bit images keyed by view, at most [`ImageCache::budget`] bytes of them, the least
/// recently used leaving first (module docs). Safe to share between threads.
pub struct ImageCache {
    budget: u64,
    inner: Mutex<CacheInner>,
}

#[derive(Default)]
struct CacheInner {
    /// Image and the tick of its last use, by key.
    entries: HashMap<usize, (Arc<Image>, u64)>,
    tick: u64,
    stats: CacheStats,
    /// Storage of images that left the cache, for the next decoded image
    /// ([`ImageCache::adopt`]); at most [`SPARE_BUFFERS`].
    spare: Vec<Vec<u8>>,
}

/// How many buffers of images that left the cache are kept for the next decodes. Reusing them
/// keeps the allocator from scattering freed images over the heap: without it, a 2 GiB cache
/// of 1000×750 images held 630 MB more at the end of a 3 000-view evaluation (measured with
/// `bbsplat train` on the `large_capture` scene, docs/scene.md).
pub const SPARE_BUFFERS: usize = 2;

impl ImageCache {
    /// An empty cache holding at most `budget` bytes of images (an image larger than the
    /// budget is handed out but not kept).
    pub fn new(budget: u64) -> Self {
        ImageCache {
            budget,
            inner: Mutex::new(CacheInner::default()),
        }
    }

    /// The most bytes of images the cache keeps.
    pub fn budget(&self) -> u64 {
        self.budget
    }

    fn lock(&self) -> MutexGuard<'_, CacheInner> {
        // A panic while holding the lock leaves a consistent map (every change is one
        // statement), so a poisoned lock is taken as it is.
        self.inner.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// The image of `key`, if held, marked as the most recently used.
    pub fn get(&self, key: usize) -> Option<Arc<Image>> {
        let mut inner = self.lock();
        inner.tick += 1;
        let tick = inner.tick;
        let found = inner.entries.get_mut(&key).map(|(image, used)| {
            *used = tick;
            Arc::clone(image)
        });
        match found {
            Some(_) => inner.stats.hits += 1,
            None => inner.stats.misses += 1,
        }
        found
    }

    /// Keeps `image` under `key` as the most recently used, first dropping the least recently
    /// used images until it fits (an image larger than the whole budget is not kept).
    pub fn insert(&self, key: usize, image: Arc<Image>) {
        let bytes = image.as_bytes().len() as u64;
        let mut inner = self.lock();
        if let Some((old, _)) = inner.entries.remove(&key) {
            inner.stats.held_bytes -= old.as_bytes().len() as u64;
        }
        if bytes > self.budget {
            return;
        }
        while inner.stats.held_bytes + bytes > self.budget {
            let Some((&oldest, _)) = inner.entries.iter().min_by_key(|(_, (_, used))| *used) else {
                break;
            };
            let (gone, _) = inner.entries.remove(&oldest).expect("the key was just found");
            inner.stats.held_bytes -= gone.as_bytes().len() as u64;
            // Kept for reuse unless a caller still holds it.
            if inner.spare.len() < SPARE_BUFFERS
                && let Ok(image) = Arc::try_unwrap(gone)
            {
                inner.spare.push(image.into_bytes());
            }
        }
        inner.tick += 1;
        let tick = inner.tick;
        inner.entries.insert(key, (image, tick));
        inner.stats.held_bytes += bytes;
        inner.stats.peak_bytes = inner.stats.peak_bytes.max(inner.stats.held_bytes);
    }

    /// `image` in the storage of an image that left the cache when one is large enough (its
    /// bytes copied, `image`'s own storage freed at once), else `image` itself. The same pixels.
    pub fn adopt(&self, image: Image) -> Image {
        let len = image.as_bytes().len();
        let spare = {
            let mut inner = self.lock();
            let found = inner.spare.iter().position(|b| b.capacity() >= len);
            found.map(|i| inner.spare.swap_remove(i))
        };
        match spare {
            Some(mut buffer) => {
                buffer.clear();
                buffer.extend_from_slice(image.as_bytes());
                Image::from_raw(image.width(), image.height(), buffer)
            }
            None => image,
        }
    }

    /// Hits, misses and bytes held so far.
    pub fn stats(&self) -> CacheStats {
        self.lock().stats
    }
}

impl fmt::Debug for ImageCache {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("ImageCache")
            .field("budget", &self.budget)
            .field("stats", &self.stats())
            .finish()
    }
}

/// What decoding a view again needs: its source record and the options it was loaded with.
pub(crate) struct Recipe {
    pub source: ViewSource,
    pub options: LoadOptions,
}

/// The image of a view decoded from its file when needed (module docs). Cloning shares the
/// recipe and the cache.
#[derive(Clone)]
pub struct OnDemandImage {
    recipe: Arc<Recipe>,
    cache: Arc<ImageCache>,
    key: usize,
    width: u32,
    height: u32,
    fingerprint: u64,
    sample_hash: u64,
}

impl OnDemandImage {
    /// The on-demand form of `image`, just decoded from `recipe` (which it leaves in `cache`).
    pub(crate) fn new(recipe: Arc<Recipe>, cache: Arc<ImageCache>, key: usize, image: Arc<Image>) -> Self {
        let made = OnDemandImage {
            recipe,
            key,
            width: image.width(),
            height: image.height(),
            fingerprint: fingerprint(&image),
            sample_hash: super::duplicates::sample_hash(&image),
            cache,
        };
        made.cache.insert(key, image);
        made
    }

    /// Width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// The image file it is decoded from.
    pub fn path(&self) -> &Path {
        &self.recipe.source.image_path
    }

    /// The cache it shares with the other views of its scene.
    pub fn cache(&self) -> &Arc<ImageCache> {
        &self.cache
    }

    /// The fingerprint of its pixels (FNV-1a 64 of the size and bytes, [`fingerprint`]).
    pub fn fingerprint(&self) -> u64 {
        self.fingerprint
    }

    /// The hash [`super::duplicates`] groups images by, kept from the first decode.
    pub(crate) fn sample_hash(&self) -> u64 {
        self.sample_hash
    }

    /// The image: from the cache, or decoded again from its file and kept in the cache.
    ///
    /// # Errors
    /// What loading the view would report now (the file is gone, unreadable or no longer
    /// decodes), or [`SceneError::ImageChanged`] when it decodes to other pixels than when the
    /// scene was loaded.
    pub fn load(&self) -> Result<Arc<Image>, SceneError> {
        if let Some(image) = self.cache.get(self.key) {
            return Ok(image);
        }
        let (view, _, _) = load_view(&self.recipe.source, &self.recipe.options)?;
        let image = match view.image {
            super::ViewImage::InMemory(image) => image,
            super::ViewImage::OnDemand(_) => unreachable!("load_view decodes into memory"),
        };
        let now = fingerprint(&image);
        if now != self.fingerprint {
            return Err(SceneError::ImageChanged {
                image: self.path().to_path_buf(),
                message: format!(
                    "it now decodes to a {}x{} image of fingerprint {now:016x}, not the {}x{} image of fingerprint {:016x} loaded at the start",
                    image.width(),
                    image.height(),
                    self.width,
                    self.height,
                    self.fingerprint
                ),
            });
        }
        let image = Arc::new(self.cache.adopt(image));
        self.cache.insert(self.key, Arc::clone(&image));
        Ok(image)
    }
}

impl PartialEq for OnDemandImage {
    /// The same file, size and pixels.
    fn eq(&self, other: &Self) -> bool {
        self.path() == other.path()
            && (self.width, self.height, self.fingerprint) == (other.width, other.height, other.fingerprint)
    }
}

impl fmt::Debug for OnDemandImage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("OnDemandImage")
            .field("path", &self.path())
            .field("width", &self.width)
            .field("height", &self.height)
            .field("fingerprint", &format_args!("{:016x}", self.fingerprint))
            .finish()
    }
}

/// FNV-1a 64 of an image's width and height (little-endian u32s) and its bytes.
pub fn fingerprint(image: &Image) -> u64 {
    let size = [image.width().to_le_bytes(), image.height().to_le_bytes()].concat();
    crate::fnv::update(crate::fnv::fnv1a(&size), image.as_bytes())
}
