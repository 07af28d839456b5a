//! `latency`: cyclictest-style wake-up latency measurement. See `latency --help`.

use clap::Parser;
use coop_tools::latency;

fn main() -> std::process::ExitCode {
    let args = latency::Args::parse();
    if let Some(latency::Attach::Attach {
        station,
        session,
        duration,
        quiet,
        json,
        ..
    }) = &args.attach
    {
        return coop_tools::run_main(|| {
            latency::attach(station, session, *duration, *quiet, json.as_deref())
        });
    }
    if let Some(latency::Attach::Vendor {
        library,
        duration,
        priority,
        json,
        ..
    }) = &args.attach
    {
        return coop_tools::run_main(|| {
            latency::vendor(library, *duration, *priority, json.as_deref()).map(|_| ())
        });
    }
    coop_tools::run_main(|| {
        let cmdline = std::env::args().collect::<Vec<_>>().join(" ");
        let report = latency::run(&args, cmdline, true)?;
        latency::print_report(&args, &report);
        if let Some(path) = &args.json {
            let text = serde_json::to_string_pretty(&latency::report_json(&args, &report))?;
            std::fs::write(path, text + "\n")
                .map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))?;
        }
        Ok(())
    })
}
