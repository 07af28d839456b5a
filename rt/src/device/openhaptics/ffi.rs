//! The loaded HD library and its entry points, as raw function pointers copied out of it; the
//! library is loaded once per process and never unloaded.

use std::ffi::{c_char, c_int, c_ulong, c_ushort, c_void, CStr};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use coop_model::body::Vec3;

use super::{OpenHapticsError, DEFAULT_DIRS, DEFAULT_LIBRARIES};

/// The constants of OpenHaptics' `hdDefines.h` this backend uses (values as the header defines).
pub(crate) mod consts {
    pub(crate) const HD_COMM_ERROR: u32 = 0x0302;
    pub(crate) const HD_COMM_CONFIG_ERROR: u32 = 0x0303;
    pub(crate) const HD_DEVICE_ALREADY_INITIATED: u32 = 0x0301;
    pub(crate) const HD_INVALID_LICENSE: u32 = 0x0600;

    pub(crate) const HD_CURRENT_BUTTONS: u32 = 0x2000;
    pub(crate) const HD_CURRENT_POSITION: u32 = 0x2050;
    pub(crate) const HD_CURRENT_VELOCITY: u32 = 0x2051;
    pub(crate) const HD_DEVICE_MODEL_TYPE: u32 = 0x2501;
    pub(crate) const HD_DEVICE_VENDOR: u32 = 0x2503;
    pub(crate) const HD_DEVICE_SERIAL_NUMBER: u32 = 0x2504;
    pub(crate) const HD_USABLE_WORKSPACE_DIMENSIONS: u32 = 0x2551;
    pub(crate) const HD_OUTPUT_DOF: u32 = 0x2554;
    pub(crate) const HD_CALIBRATION_STYLE: u32 = 0x2555;
    pub(crate) const HD_NOMINAL_MAX_STIFFNESS: u32 = 0x2602;
    pub(crate) const HD_NOMINAL_MAX_CONTINUOUS_FORCE: u32 = 0x2604;
    pub(crate) const HD_NOMINAL_MAX_DAMPING: u32 = 0x2609;
    pub(crate) const HD_CURRENT_FORCE: u32 = 0x2700;

    pub(crate) const HD_FORCE_OUTPUT: u32 = 0x4000;
    pub(crate) const HD_MAX_FORCE_CLAMPING: u32 = 0x4001;
    pub(crate) const HD_FORCE_RAMPING: u32 = 0x4002;

    pub(crate) const HD_CALIBRATION_OK: u32 = 0x5000;
    pub(crate) const HD_CALIBRATION_NEEDS_UPDATE: u32 = 0x5001;
    pub(crate) const HD_CALIBRATION_AUTO: u32 = 1 << 1;
    pub(crate) const HD_CALIBRATION_INKWELL: u32 = 1 << 2;

    pub(crate) const HD_INVALID_HANDLE: u32 = 0xFFFF_FFFF;
    pub(crate) const HD_CALLBACK_DONE: u32 = 0;
    pub(crate) const HD_CALLBACK_CONTINUE: u32 = 1;
    pub(crate) const HD_MAX_SCHEDULER_PRIORITY: u16 = 0xFFFF;
}

use consts::HD_CURRENT_FORCE;

/// `HDErrorInfo`, returned by value from `hdGetError`.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub(crate) struct HdErrorInfo {
    pub(crate) error_code: u32,
    pub(crate) internal_error_code: c_int,
    pub(crate) hhd: u32,
}

/// `HDSchedulerCallback`: `HDCallbackCode (*)(void *pUserData)`.
pub(crate) type Callback = unsafe extern "C" fn(*mut c_void) -> u32;

type InitDevice = unsafe extern "C" fn(*const c_char) -> u32;
type ByHandle = unsafe extern "C" fn(u32);
type GetError = unsafe extern "C" fn() -> HdErrorInfo;
type GetErrorString = unsafe extern "C" fn(u32) -> *const c_char;
type ByEnum = unsafe extern "C" fn(u32);
type GetDoublev = unsafe extern "C" fn(u32, *mut f64);
type GetIntegerv = unsafe extern "C" fn(u32, *mut c_int);
type GetString = unsafe extern "C" fn(u32) -> *const c_char;
type SetDoublev = unsafe extern "C" fn(u32, *const f64);
type CheckCalibration = unsafe extern "C" fn() -> u32;
type ScheduleAsynchronous = unsafe extern "C" fn(Callback, *mut c_void, c_ushort) -> c_ulong;
type Unschedule = unsafe extern "C" fn(c_ulong);
type NoArgs = unsafe extern "C" fn();
type SetRate = unsafe extern "C" fn(c_ulong);

/// The HD entry points we use. The function pointers stay valid for the process's life: the
/// library is never unloaded (`_lib` is leaked with the `Api`).
#[derive(Debug)]
pub(crate) struct Api {
    pub(crate) file: String,
    init_device: InitDevice,
    disable_device: ByHandle,
    make_current_device: ByHandle,
    begin_frame: ByHandle,
    end_frame: ByHandle,
    get_error: GetError,
    get_error_string: GetErrorString,
    enable: ByEnum,
    disable: ByEnum,
    get_doublev: GetDoublev,
    get_integerv: GetIntegerv,
    get_string: GetString,
    set_doublev: SetDoublev,
    check_calibration: CheckCalibration,
    update_calibration: ByEnum,
    schedule_asynchronous: ScheduleAsynchronous,
    unschedule: Unschedule,
    start_scheduler: NoArgs,
    stop_scheduler: NoArgs,
    set_scheduler_rate: SetRate,
    _lib: libloading::Library,
}

/// Every library loaded in this process, by the path it was asked for (or "" for the search).
static LOADED: Mutex<Vec<(PathBuf, &'static Api)>> = Mutex::new(Vec::new());

impl Api {
    /// The library at `configured` (or found by the default search), loaded on first use and kept
    /// for the process's life.
    pub(crate) fn load(configured: Option<&Path>) -> Result<&'static Self, OpenHapticsError> {
        let key = configured.map(Path::to_path_buf).unwrap_or_default();
        let mut loaded = LOADED
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some((_, api)) = loaded.iter().find(|(k, _)| *k == key) {
            return Ok(api);
        }
        let api: &'static Self = Box::leak(Box::new(Self::open(configured)?));
        loaded.push((key, api));
        Ok(api)
    }

    fn open(configured: Option<&Path>) -> Result<Self, OpenHapticsError> {
        let (lib, file) =
            crate::device::vendor_lib::load(configured, DEFAULT_LIBRARIES, DEFAULT_DIRS).map_err(
                |m| OpenHapticsError::LibraryMissing {
                    file: m.file,
                    reason: m.reason,
                },
            )?;
        macro_rules! sym {
            ($name:literal) => {{
                // The symbol's type is OpenHaptics' declaration of that function in hd.h or
                // hdScheduler.h (argument and return types as C declares them: HHD, HDenum and
                // HDerror are unsigned int, HDushort unsigned short, HDulong and
                // HDSchedulerHandle unsigned long); the pointer is copied out and the library is
                // never unloaded.
                // SAFETY: the type matches the C declaration and the library outlives it (above).
                let s = unsafe { lib.get(concat!($name, "\0").as_bytes()) };
                *s.map_err(|_| OpenHapticsError::MissingSymbol {
                    file: file.clone(),
                    symbol: $name,
                })?
            }};
        }
        Ok(Self {
            init_device: sym!("hdInitDevice"),
            disable_device: sym!("hdDisableDevice"),
            make_current_device: sym!("hdMakeCurrentDevice"),
            begin_frame: sym!("hdBeginFrame"),
            end_frame: sym!("hdEndFrame"),
            get_error: sym!("hdGetError"),
            get_error_string: sym!("hdGetErrorString"),
            enable: sym!("hdEnable"),
            disable: sym!("hdDisable"),
            get_doublev: sym!("hdGetDoublev"),
            get_integerv: sym!("hdGetIntegerv"),
            get_string: sym!("hdGetString"),
            set_doublev: sym!("hdSetDoublev"),
            check_calibration: sym!("hdCheckCalibration"),
            update_calibration: sym!("hdUpdateCalibration"),
            schedule_asynchronous: sym!("hdScheduleAsynchronous"),
            unschedule: sym!("hdUnschedule"),
            start_scheduler: sym!("hdStartScheduler"),
            stop_scheduler: sym!("hdStopScheduler"),
            set_scheduler_rate: sym!("hdSetSchedulerRate"),
            file: file.clone(),
            _lib: lib,
        })
    }

    pub(crate) fn init_device(&self, name: Option<&CStr>) -> u32 {
        let p = name.map_or(std::ptr::null(), CStr::as_ptr);
        // SAFETY: hdInitDevice(HDstring) takes NULL (HD_DEFAULT_DEVICE) or a NUL-terminated name
        // that outlives the call.
        unsafe { (self.init_device)(p) }
    }

    pub(crate) fn disable_device(&self, h: u32) {
        // SAFETY: hdDisableDevice(HHD) on a handle hdInitDevice returned.
        unsafe { (self.disable_device)(h) }
    }

    pub(crate) fn make_current(&self, h: u32) {
        // SAFETY: hdMakeCurrentDevice(HHD) on a handle hdInitDevice returned.
        unsafe { (self.make_current_device)(h) }
    }

    pub(crate) fn begin_frame(&self, h: u32) {
        // SAFETY: hdBeginFrame(HHD), called on the scheduler's thread inside its callback.
        unsafe { (self.begin_frame)(h) }
    }

    pub(crate) fn end_frame(&self, h: u32) {
        // SAFETY: hdEndFrame(HHD), closing the frame the same callback opened.
        unsafe { (self.end_frame)(h) }
    }

    /// The newest error on the HD API's stack, popped (`None`: success).
    pub(crate) fn take_error(&self) -> Option<u32> {
        // SAFETY: hdGetError() takes nothing and returns HDErrorInfo by value (a #[repr(C)] copy
        // of its three fields).
        let e = unsafe { (self.get_error)() };
        (e.error_code != 0).then_some(e.error_code)
    }

    /// Pops every error on the stack (bounded: the stack is finite).
    pub(crate) fn drain_errors(&self) {
        for _ in 0..64 {
            if self.take_error().is_none() {
                break;
            }
        }
    }

    pub(crate) fn error_string(&self, code: u32) -> String {
        // SAFETY: hdGetErrorString(HDerror) returns NULL or a static NUL-terminated string.
        let p = unsafe { (self.get_error_string)(code) };
        if p.is_null() {
            return "no description".into();
        }
        // SAFETY: non-null and NUL-terminated (above).
        unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
    }

    pub(crate) fn enable(&self, cap: u32) {
        // SAFETY: hdEnable(HDenum) with one of hdDefines.h's capabilities.
        unsafe { (self.enable)(cap) }
    }

    pub(crate) fn disable(&self, cap: u32) {
        // SAFETY: hdDisable(HDenum) with one of hdDefines.h's capabilities.
        unsafe { (self.disable)(cap) }
    }

    /// `N` doubles of parameter `p` (NaN where the call wrote none).
    pub(crate) fn doubles<const N: usize>(&self, p: u32) -> [f64; N] {
        const { assert!(N <= 16, "at most a transform's sixteen doubles") };
        // The HD API writes as many values as the parameter has; the buffer holds the largest any
        // parameter has (a transform's sixteen), so a parameter longer than asked for cannot
        // write past it.
        let mut out = [f64::NAN; 16];
        // SAFETY: hdGetDoublev(HDenum, HDdouble*) writes at most 16 doubles (a transform, the
        // largest parameter) through a valid pointer to a local array of 16.
        unsafe { (self.get_doublev)(p, out.as_mut_ptr()) };
        std::array::from_fn(|k| out[k])
    }

    /// Integer parameter `p` (0 where the call wrote none).
    pub(crate) fn integer(&self, p: u32) -> c_int {
        let mut out: [c_int; 16] = [0; 16];
        // SAFETY: hdGetIntegerv(HDenum, HDint*) writes at most 16 ints through a valid pointer to
        // a local array of 16.
        unsafe { (self.get_integerv)(p, out.as_mut_ptr()) };
        out[0]
    }

    pub(crate) fn string(&self, p: u32) -> Option<String> {
        // SAFETY: hdGetString(HDenum) returns NULL or a NUL-terminated string the library owns.
        let s = unsafe { (self.get_string)(p) };
        if s.is_null() {
            return None;
        }
        // SAFETY: non-null and NUL-terminated (above); copied before the next call.
        Some(unsafe { CStr::from_ptr(s) }.to_string_lossy().into_owned())
    }

    /// Sets the frame's force, N, device frame.
    pub(crate) fn set_force(&self, f: Vec3) {
        let v = [f.x, f.y, f.z];
        // SAFETY: hdSetDoublev(HDenum, const HDdouble*) reads the three doubles of
        // HD_CURRENT_FORCE from a valid local array.
        unsafe { (self.set_doublev)(HD_CURRENT_FORCE, v.as_ptr()) }
    }

    pub(crate) fn check_calibration(&self) -> u32 {
        // SAFETY: hdCheckCalibration() takes nothing and returns an HDenum.
        unsafe { (self.check_calibration)() }
    }

    pub(crate) fn update_calibration(&self, style: u32) {
        // SAFETY: hdUpdateCalibration(HDenum) with a style the device reported.
        unsafe { (self.update_calibration)(style) }
    }

    /// Schedules `cb` with `data` at the highest priority; 0 when the scheduler refused.
    ///
    /// # Safety
    /// `data` must stay valid for `cb` until [`Api::unschedule`] (after [`Api::stop_scheduler`])
    /// has returned.
    pub(crate) unsafe fn schedule(&self, cb: Callback, data: *mut c_void) -> c_ulong {
        // SAFETY: hdScheduleAsynchronous(HDSchedulerCallback, void*, HDushort); the caller keeps
        // `data` valid for as long as the callback may run (this function's contract).
        unsafe { (self.schedule_asynchronous)(cb, data, consts::HD_MAX_SCHEDULER_PRIORITY) }
    }

    pub(crate) fn unschedule(&self, h: c_ulong) {
        // SAFETY: hdUnschedule(HDSchedulerHandle) on a handle hdScheduleAsynchronous returned.
        unsafe { (self.unschedule)(h) }
    }

    pub(crate) fn start_scheduler(&self) {
        // SAFETY: hdStartScheduler() takes nothing.
        unsafe { (self.start_scheduler)() }
    }

    pub(crate) fn stop_scheduler(&self) {
        // SAFETY: hdStopScheduler() takes nothing; it returns once the scheduler's thread is done.
        unsafe { (self.stop_scheduler)() }
    }

    pub(crate) fn set_scheduler_rate(&self, hz: u32) {
        // SAFETY: hdSetSchedulerRate(HDulong) with a rate validate() allowed.
        unsafe { (self.set_scheduler_rate)(c_ulong::from(hz)) }
    }
}
