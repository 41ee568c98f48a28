//! skinflow recording format v1 (CONTRACTS.md section 2): writing, reading, replay, inspect.
//!
//! `RecordingWriter` (module `write`) appends rows of the declared streams and writes them a
//! chunk at a time, flushing at least every `flush_interval_s`, rotating parts by size or time.
//! `Recording::open` (module `read`) validates a file from any writer (skinflow, h5py, MATLAB:
//! any numeric element type, but times must be floats, as integer times are most likely
//! milliseconds or ticks) and loads its streams; `Recording::events` (module `replay`) merges them in time order;
//! `Recording::no_load` (module `tare`) finds the leading no-load period; `inspect` summarises;
//! `repair` salvages a file whose last write was cut short.
//! Plain library: no engine types; the `hdf5_logger` and `replay` nodes wrap it.
//!
//! # Recording format: skinflow's extras
//!
//! Files follow CONTRACTS.md section 2. The logger also writes the following, which readers
//! of the contract ignore (extra groups and attributes are allowed).
//!
//! | path | type, shape | meaning |
//! |---|---|---|
//! | `/` attr `software_version` | string | writer and version, e.g. `skinflow 0.1.0` |
//! | `/` attr `part` | u32 | 1-based index of a rotated part (only when rotating) |
//! | `/derived/image` | f64 `[n, H, W]` | reconstructed conductivity-change images, row-major, as the pipeline produced them |
//! | `/derived/image_t` | f64 `[n]` | seconds, time of the EIT frame each image comes from |
//! | `/derived/contacts/t` | f64 `[n]` | seconds |
//! | `/derived/contacts/x_mm`, `y_mm` | f64 `[n, Cmax]` | segmented contact centroids, NaN-padded |
//! | `/derived/contacts/sum` | f64 `[n, Cmax]` | conductivity sum of each contact (image units) |
//! | `/derived/contacts/area_mm2` | f64 `[n, Cmax]` | contact area, mm² |
//! | `/derived/forces/<strategy>/t` | f64 `[n]` | seconds |
//! | `/derived/forces/<strategy>/force_n` | f64 `[n, Cmax]` | per-contact force of that strategy, N, in the order of the frame's contacts, NaN-padded |
//! | `/derived/forces/<strategy>/dp_kpa` | f64 `[n, Cmax]` | each contact's pressure share from the splitter, kPa, NaN-padded (the pneumatic strategies' input; the EIT strategies use the contact's conductivity sum instead) |
//! | `/derived/forces/<strategy>/flags` | f64 `[n, Cmax]` | guard bits of each force (integer values, NaN-padded): 1 no load (signal <= 0, force 0), 2 above and 4 below the calibrated range (extrapolated), 8 centroid clamped onto the calibrated region, 16 area clamped, 32 negative force clamped to 0, 64 no pressure (the frame's dP is unknown: force 0 is a placeholder, bit 1 not set), 128 contacts dropped (the frame had more regions than the segmenter's `max_contacts`: the pressure change was shared over the reported ones only, so pneumatic forces are biased high) (`layout::force_flags`). Plugin lanes carry only bits 1, 64 and 128, the first two set where their share is <= 0 or NaN |
//! | `/derived/sync/t` | f64 `[n]` | seconds, time of the EIT frame |
//! | `/derived/sync/dp_kpa` | f64 `[n]` | the frame's pressure change: window mean minus P0, kPa (NaN without samples or while P0 is unknown) |
//! | `/derived/sync/pressure_samples`, `pressure_sd_kpa` | f64 `[n]` | samples in the window and their SD, kPa (NaN with fewer than 2) |
//! | `/derived/sync/settled` | f64 `[n]` | 1 where the pressure alone says the load did not change during the window, else 0 |
//! | `/derived/sync/no_load` | f64 `[n]` | 1 for frames of the leading no-load period, else 0 |
//! | `/derived/sync/p0_kpa`, `noise_kpa` | f64 `[n]` | the no-load offset removed and the noise SD behind `settled`, kPa (NaN until known) |
//!
//! - Derived streams are joined to each other and to `/eit` by time `t`, not by row index: with
//!   `drop_oldest` edges each stream may lose different frames (counted by the engine), and
//!   with rotation a frame's rows may fall into consecutive parts.
//! - Widths are fixed when a file is created, so rows never change once written and all parts
//!   have the same shapes:
//!   truth C = `truth_max_contacts` (default 8) and derived Cmax = `derived_max_contacts`
//!   (default 16). Unused columns hold NaN. A truth row with more contacts than C is refused
//!   (an error, never silent); derived contacts beyond Cmax are dropped and counted.
//! - Every declared stream's datasets exist from the start, empty until rows arrive.
//! - Storage: chunked along rows, resizable, shuffle + deflate (level 1 by default); the chunk
//!   holds up to `chunk_rows` rows (default 1024), fewer when a row is wide, so a chunk stays
//!   near 1 MiB. Fill value NaN (0 for `/eit/seq`). Object modification times are not stored.
//! - Library version bounds: `earliest..v18` (readable by HDF5 1.8 and Debian's 1.10 tools),
//!   or `v110..v110` with SWMR on (readable by HDF5 >= 1.10).
//! - Crash safety: rows stay in memory until their chunk is full or `flush_interval_s` (wall
//!   clock, default 1 s) has passed, then they are written and the file is flushed; the file is
//!   not touched between flushes, so after a SIGKILL it opens with every row up to the last
//!   flush. A file killed while in SWMR mode keeps HDF5's "open for writing" mark; `Recording::open`
//!   then opens it in SWMR-read mode (other tools: `h5clear -s FILE` removes the mark).
//!   A new file (or part) is built under a hidden name beside it, `.NAME.PID.partial`, and
//!   renamed (without `overwrite`: hard-linked, which refuses to replace a file) once its
//!   structure is flushed: until then HDF5 has no valid superblock on disk, and a kill in that
//!   window used to leave an unreadable file under the recording's name. A killed writer may
//!   leave its `.partial` file behind; the recording's name only ever shows a file that opens.
//!
//! # Rotation and file names
//!
//! With `rotate_mb` or `rotate_s` set, the writer never writes the path it was given: for
//! `rec.h5` it writes `rec-0001.h5`, `rec-0002.h5`, ... (1-based, 4 digits or more, next to
//! `rec.h5`; see `rotate::part_path`, and `rotate::find_parts` to list them). A new part starts
//! before the first row appended after the current part reached `rotate_mb` MB (10^6 bytes, as
//! measured after a flush) or before the first row whose time is `rotate_s` seconds or more after
//! the part's first row. Each row is in exactly one part, and each part is a complete format-v1
//! file with the same root attributes (plus `part`) and `/eit/reference` when set. Its truth
//! starts with the row in effect when it starts (the last truth row appended before it, at
//! that row's own time, which is before the part's other rows), so each part alone gives every
//! frame its truth, and a part that starts while a load is held has no leading no-load period.
//! That row is the one exception to "each row is in exactly one part": it repeats the previous
//! part's last truth row, so a tool joining the parts into one stream drops the first truth row
//! of every part but the first. `rotate::recording_files` turns the path the writer was
//! given into the list of files to replay in order.
//!
//! # Reading
//!
//! `Recording::open` loads every stream whole (an hour of 120-value frames at 100 Hz is
//! ~350 MB); rotation keeps parts small. It is strict: a file whose datasets disagree in
//! length is refused, so a file still being written in SWMR mode may be refused mid-update
//! (retry, or follow it with h5py's SWMR reader). A file whose last flush was cut short (one
//! table's datasets of different lengths) is refused too; `repair` (module `repair`) writes a
//! copy with each table cut to the rows all its datasets hold.

pub mod error;
pub mod inspect;
pub mod layout;
pub mod read;
pub mod repair;
pub mod replay;
pub mod rotate;
pub mod tare;
mod timestamp;
pub mod write;

pub use error::{RecordError, SchemaProblem};
pub use inspect::{FrameGaps, GUARDS, GuardCounts, StreamSummary, Summary, SyncCounts, TruthCoverage, inspect};
pub use read::{
    ContactsStream, Derived, EitStream, ForceStream, ImageStream, PressureStream, Recording, SyncStream, TruthRow,
    TruthStream,
};
pub use repair::{RepairReport, TableCut, repair};
pub use replay::{Event, Events};
pub use tare::{DEFAULT_TARE_S, NoLoad, NoLoadSource};
pub use timestamp::iso8601_utc;
pub use write::{ContactRow, ForceRow, RecordingWriter, Streams, SyncRow, TruthContact, WriterOptions, WriterStats};
