//! `bbsplat train --view`: a live view of the training, served on 127.0.0.1 by [`super::http`]
//! (the server of `view --serve`, with all its safety: loopback `Host` only, bounded and timed
//! requests, clients served side by side).
//!
//! Three threads share the state:
//!
//! - the training thread calls [`LiveView::step`] after every step (it stores a few numbers
//!   under a mutex held only to copy them) and [`LiveView::snapshot`] every `--view-every` steps
//!   with the activated billboards ([`bbsplat::train::TrainEvent::Snapshot`]), which it hands
//!   over with a `try_send` on a one-slot channel: when the encoder is still busy with the
//!   previous snapshot, this one is dropped, so training never waits;
//! - the encoder thread turns a snapshot into the viewer's model JSON
//!   ([`bbsplat::export::viewer::viewer_data`]) and bumps the model version;
//! - the server answers `/` (the viewer page, live), `/status` (JSON: step, loss, running PSNR,
//!   last test PSNR, the step's camera, the model version), `/model` (the latest model JSON) and
//!   `/refresh` (raises the run's [`SnapshotRequest`]: the model after the next step is encoded,
//!   whatever `--view-every` says; the page's "refresh now" button and its `r` key ask it).
//!   A response's body is an `Arc` taken under the lock and written after it is released, so a
//!   slow client holds nothing.
//!
//! The encoder and the server run at the lowest scheduling priority (nice 19, Linux): they use
//! the time the training leaves idle.

use super::http;
use anyhow::Result;
use bbsplat::billboards::ActivatedBillboards;
use bbsplat::camera::Camera;
use bbsplat::export::viewer::{ViewerCamera, page_of_data, viewer_data};
use bbsplat::train::SnapshotRequest;
use glam::Vec3;
use serde_json::json;
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::sync::{Arc, Mutex, PoisonError};

/// The numbers of the latest step, as `/status` reports them.
#[derive(Clone, Copy, Debug, Default)]
struct Progress {
    /// Steps done.
    step: usize,
    /// Steps of the run.
    iterations: usize,
    /// Total loss of the latest step.
    loss: f64,
    /// Running (moving-average) PSNR of the steps, dB.
    running_psnr: f64,
    /// The latest intermediate test PSNR, dB.
    test_psnr: Option<f64>,
    /// Index of the latest step's view in the training views.
    view: usize,
    /// Whether the run ended (finished or stopped).
    done: bool,
}

/// The latest encoded model.
struct Encoded {
    /// Counts the models encoded, from 1.
    version: u64,
    /// The step it is of.
    step: usize,
    /// Its [`viewer_data`] JSON.
    json: Arc<Vec<u8>>,
}

/// What the three threads share.
struct Shared {
    progress: Mutex<Progress>,
    model: Mutex<Encoded>,
    /// The training views' names and cameras, in the trainer's order.
    cameras: Vec<(String, Camera)>,
    sh_degree: u32,
    background: Vec3,
}

impl Shared {
    fn encode(&self, billboards: &ActivatedBillboards) -> Vec<u8> {
        let cameras: Vec<ViewerCamera> = self
            .cameras
            .iter()
            .map(|(name, camera)| ViewerCamera { name, camera })
            .collect();
        viewer_data(&billboards.borrowed(), self.sh_degree, self.background, &cameras).into_bytes()
    }

    fn status(&self) -> Vec<u8> {
        let p = *self.progress.lock().unwrap_or_else(PoisonError::into_inner);
        let (version, model_step) = {
            let m = self.model.lock().unwrap_or_else(PoisonError::into_inner);
            (m.version, m.step)
        };
        let camera = self.cameras.get(p.view).map(|(name, c)| {
            let m = c.rotation;
            json!({
                "index": p.view,
                "name": name,
                "rotation": [m.row(0).to_array(), m.row(1).to_array(), m.row(2).to_array()],
                "translation": c.translation.to_array(),
                "fx": c.fx, "fy": c.fy, "cx": c.cx, "cy": c.cy,
                "width": c.width, "height": c.height,
            })
        });
        let finite = |x: f64| x.is_finite().then_some(x);
        json!({
            "step": p.step,
            "iterations": p.iterations,
            "loss": finite(p.loss),
            "running_psnr": finite(p.running_psnr),
            "test_psnr": p.test_psnr.and_then(finite),
            "camera": camera,
            "model_version": version,
            "model_step": model_step,
            "done": p.done,
        })
        .to_string()
        .into_bytes()
    }
}

/// The training side of a live view (see the [module documentation](self)).
pub struct LiveView {
    shared: Arc<Shared>,
    snapshots: SyncSender<(usize, Arc<ActivatedBillboards>)>,
}

impl LiveView {
    /// Binds 127.0.0.1:`port` (0: any free port), starts the encoder and the server threads with
    /// `initial` as the first model, and returns the view and the address it serves. A `GET
    /// /refresh` raises `refresh` (the run's [`bbsplat::train::RunConfig::snapshot_request`]).
    pub fn start(
        port: u16,
        initial: &ActivatedBillboards,
        step: usize,
        cameras: Vec<(String, Camera)>,
        sh_degree: u32,
        background: Vec3,
        refresh: SnapshotRequest,
    ) -> Result<(Self, std::net::SocketAddr)> {
        let listener = http::bind(port)?;
        let address = listener.local_addr()?;
        let mut shared = Shared {
            progress: Mutex::new(Progress {
                step,
                view: usize::MAX,
                ..Progress::default()
            }),
            model: Mutex::new(Encoded {
                version: 1,
                step,
                json: Arc::new(Vec::new()),
            }),
            cameras,
            sh_degree,
            background,
        };
        let first = shared.encode(initial);
        // The page embeds the first model and is told it is live (`data.live`).
        let mut data: serde_json::Value =
            anyhow::Context::context(serde_json::from_slice(&first), "the viewer's model data")?;
        let Some(fields) = data.as_object_mut() else {
            anyhow::bail!("the viewer's model data is not a JSON object");
        };
        fields.insert("live".into(), serde_json::Value::Bool(true));
        let page = Arc::new(page_of_data(&data.to_string()).into_bytes());
        shared.model.get_mut().unwrap_or_else(PoisonError::into_inner).json = Arc::new(first);
        let shared = Arc::new(shared);
        let (snapshots, received) = sync_channel(1);
        let encoder = Arc::clone(&shared);
        std::thread::Builder::new()
            .name("bbsplat-live-encode".into())
            .spawn(move || {
                lowest_priority();
                encode_loop(&encoder, &received)
            })?;
        let server = Arc::clone(&shared);
        let handler = move |target: &str| {
            let path = target.split(['?', '#']).next().unwrap_or_default();
            let (content_type, body) = match path {
                "/" | "/index.html" => ("text/html; charset=utf-8", Arc::clone(&page)),
                "/status" => ("application/json", Arc::new(server.status())),
                "/model" => (
                    "application/json",
                    Arc::clone(&server.model.lock().unwrap_or_else(PoisonError::into_inner).json),
                ),
                // Loopback only, like every path here; asking twice before a step asks once.
                "/refresh" => {
                    refresh.request();
                    ("application/json", Arc::new(br#"{"requested":true}"#.to_vec()))
                }
                _ => return None,
            };
            Some(http::Response {
                status: "200 OK",
                content_type,
                body,
            })
        };
        std::thread::Builder::new()
            .name("bbsplat-live-serve".into())
            .spawn(move || {
                // The connection threads it starts inherit the priority.
                lowest_priority();
                http::serve(listener, Arc::new(handler))
            })?;
        Ok((Self { shared, snapshots }, address))
    }

    /// Records a step's numbers (called on the training thread; takes a lock held only by
    /// copies of a few numbers).
    pub fn step(&self, step: usize, iterations: usize, loss: f64, running_psnr: f64, view: usize) {
        let mut p = self.shared.progress.lock().unwrap_or_else(PoisonError::into_inner);
        (p.step, p.iterations, p.loss, p.running_psnr, p.view) = (step, iterations, loss, running_psnr, view);
    }

    /// Records an intermediate test PSNR.
    pub fn evaluation(&self, psnr: f64) {
        self.shared
            .progress
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .test_psnr = Some(psnr);
    }

    /// Marks the run as ended.
    pub fn done(&self) {
        self.shared.progress.lock().unwrap_or_else(PoisonError::into_inner).done = true;
    }

    /// Hands `billboards` to the encoder unless it is still busy (then this snapshot is dropped:
    /// training never waits for the live view).
    pub fn snapshot(&self, step: usize, billboards: &Arc<ActivatedBillboards>) {
        match self.snapshots.try_send((step, Arc::clone(billboards))) {
            Ok(()) | Err(TrySendError::Full(_)) | Err(TrySendError::Disconnected(_)) => {}
        }
    }
}

/// Lowers the calling thread's scheduling priority to the lowest (nice 19; Linux keeps one per
/// thread, and threads started from it inherit it), so that the live view runs on time the
/// training leaves idle: on a machine whose cores the training's workers keep busy, a worker
/// sharing its core with the encoder would hold up every fork-join of the step. Elsewhere, and
/// if the call fails, the priority stays as it is (the view still works).
fn lowest_priority() {
    #[cfg(target_os = "linux")]
    // SAFETY: `gettid` takes no argument and returns the calling thread's id; `setpriority` with
    // `PRIO_PROCESS` and that id changes only this thread's nice value and reads no memory.
    unsafe {
        let thread = libc::syscall(libc::SYS_gettid) as libc::id_t;
        libc::setpriority(libc::PRIO_PROCESS, thread, 19);
    }
}

/// The encoder thread: each snapshot received becomes the next model version.
fn encode_loop(shared: &Shared, received: &Receiver<(usize, Arc<ActivatedBillboards>)>) {
    while let Ok((step, billboards)) = received.recv() {
        let json = Arc::new(shared.encode(&billboards));
        drop(billboards);
        let mut model = shared.model.lock().unwrap_or_else(PoisonError::into_inner);
        model.version += 1;
        model.step = step;
        model.json = json;
    }
}
