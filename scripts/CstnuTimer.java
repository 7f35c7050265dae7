// The CSTNU Tool's STNU DC check timed in one long-running JVM, one file at a time as asked on standard
// input, so that scripts/bench_dc.py can interleave it with hrc's check instance by instance (the JVM's
// start is never timed, and its JIT warms over the run as hrc's caches do).
//
// Input lines: PATH<TAB>REPEAT. Output, one line each: DC|NOT_DC<TAB>median_ns<TAB>min_ns, or ERROR<TAB>why.
// As ../shared/oracles/cstnu-tool/CstnuCheck.java times it: the file read with the tool's TNGraphMLReader
// (not timed), one untimed check, then REPEAT checks, each on a fresh copy of the graph in a fresh STNU (the
// copy not timed; the tool's own preparation, initAndCheck, timed with the check, as its Checker does).
// Built and run by scripts/bench_dc.py (javac from a JDK; classpath: the oracle's jar and Debian's jars).
import it.univr.di.cstnu.algorithms.STNU;
import it.univr.di.cstnu.algorithms.STNU.CheckAlgorithm;
import it.univr.di.cstnu.graph.STNUEdge;
import it.univr.di.cstnu.graph.STNUEdgeInt;
import it.univr.di.cstnu.graph.TNGraph;
import it.univr.di.cstnu.graph.TNGraphMLReader;

import java.io.BufferedReader;
import java.io.File;
import java.io.FileDescriptor;
import java.io.FileOutputStream;
import java.io.InputStreamReader;
import java.io.PrintStream;
import java.nio.charset.StandardCharsets;
import java.util.Arrays;
import java.util.logging.Level;
import java.util.logging.Logger;

public final class CstnuTimer {
	private CstnuTimer() {
	}

	public static void main(String[] args) throws Exception {
		Logger.getLogger("").setLevel(Level.OFF);
		final PrintStream out = new PrintStream(new FileOutputStream(FileDescriptor.out), true, StandardCharsets.UTF_8);
		System.setOut(System.err);  // whatever the tool prints stays off the result stream
		final CheckAlgorithm alg = CheckAlgorithm.RUL2021;
		final BufferedReader in = new BufferedReader(new InputStreamReader(System.in, StandardCharsets.UTF_8));
		String line;
		while ((line = in.readLine()) != null) {
			final String[] parts = line.split("\t");
			final int repeat = Math.max(1, Integer.parseInt(parts[1]));
			try {
				final TNGraph<STNUEdge> g = new TNGraphMLReader<STNUEdge>().readGraph(new File(parts[0]), STNUEdgeInt.class);
				final boolean dc = new STNU(new TNGraph<>(g, STNUEdgeInt.class)).dynamicControllabilityCheck(alg)
					.isControllable();
				final long[] ns = new long[repeat];
				for (int r = 0; r < repeat; r++) {
					final STNU fresh = new STNU(new TNGraph<>(g, STNUEdgeInt.class));
					final long t0 = System.nanoTime();
					fresh.dynamicControllabilityCheck(alg);
					ns[r] = System.nanoTime() - t0;
				}
				Arrays.sort(ns);
				out.println((dc ? "DC" : "NOT_DC") + "\t" + ns[repeat / 2] + "\t" + ns[0]);
			} catch (Throwable e) {
				out.println("ERROR\t" + (e.getClass().getSimpleName() + ": " + e.getMessage()).replace("\n", " ").replace("\t", " "));
			}
		}
	}
}
