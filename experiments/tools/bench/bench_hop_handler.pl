/*  The handler of the agent that dfrl bench migrate moves between its
    home and the peer (included by bench_migrate.pl and profile_hop.pl, so
    that both time the same code and the same sandbox check): at every
    arrival it records the hop's time since its departure and the CPU
    time its process has used so far (statistics(process_cputime): all
    threads, user and system), and after Hops hops, back home, prints the
    CPU stamps as CPU_S [[Port, Seconds], ...] (one per arrival, the
    start at home first) and then the times as LATENCIES_MS [...].
*/

bench(guid, (_, Port), main) :-
    get_time(Now),
    statistics(process_cputime, Cpu),
    retract(cpu(guid, C0)),
    assertz(cpu(guid, [[Port, Cpu]|C0])),
    (   retract(departed(guid, T0))
    ->  Ms is (Now - T0) * 1000,
        retract(lat(guid, L0)),
        assertz(lat(guid, [Ms|L0]))
    ;   true
    ),
    lat(guid, L),
    length(L, Done),
    plan(guid, plan(Home, Peer, Hops)),
    (   Port =:= Home -> Next = Peer ; Next = Home ),
    (   Done >= Hops
    ->  (   Port =:= Home
        ->  reverse(L, InOrder),
            cpu(guid, Cs),
            reverse(Cs, CpuInOrder),
            format(user_output, "CPU_S ~w~n", [CpuInOrder]),
            format(user_output, "LATENCIES_MS ~w~n", [InOrder]),
            flush_output
        ;   move_agent(guid, (localhost, Home))
        )
    ;   get_time(T1),
        assertz(departed(guid, T1)),
        move_agent(guid, (localhost, Next))
    ).
