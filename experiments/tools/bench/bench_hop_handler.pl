/*  The handler of the agent that dfrl bench migrate moves between its
    home and the peer (included by bench_migrate.pl and profile_hop.pl, so
    that both time the same code and the same sandbox check).

    At every arrival it takes the time of the hop since its departure and
    the CPU time its process has used so far (statistics(process_cputime):
    all threads, user and system). Home prints them, one line per arrival
    in the order of the arrivals:

        ARRIVAL Ms Port Seconds     (Ms is `-` for an arrival that ends no
                                     timed hop: the start, the last return)

    The agent carries at most 64 such stamps: home prints them when it
    holds that many, and at the end, followed by ARRIVALS_END. So its
    payload does not grow with the number of hops (a list of every hop's
    figures, carried, made a long run measure a growing payload), and the
    reader of home's output is woken once in 64 arrivals, not during every
    hop (a reader woken at every arrival slowed the 10,000-float hop it
    measured by 10-35% on 2 cores).
*/

bench(guid, (_, Port), main) :-
    get_time(Now),
    statistics(process_cputime, Cpu),
    (   retract(departed(guid, T0))
    ->  Ms is (Now - T0) * 1000,
        retract(done(guid, D0)),
        D is D0 + 1,
        assertz(done(guid, D))
    ;   Ms = (-)
    ),
    retract(unsaid(guid, Unsaid0)),
    Unsaid = [arrival(Ms, Port, Cpu)|Unsaid0],
    done(guid, Done),
    plan(guid, plan(Home, Peer, Hops)),
    (   Port =:= Home -> Next = Peer ; Next = Home ),
    length(Unsaid, Carried),
    (   Port =:= Home,
        ( Done >= Hops ; Carried >= 64 )
    ->  reverse(Unsaid, InOrder),
        forall(member(arrival(M, P, C), InOrder),
               format(user_output, "ARRIVAL ~w ~w ~w~n", [M, P, C])),
        flush_output,
        assertz(unsaid(guid, []))
    ;   assertz(unsaid(guid, Unsaid))
    ),
    (   Done >= Hops
    ->  (   Port =:= Home
        ->  format(user_output, "ARRIVALS_END~n", []),
            flush_output
        ;   move_agent(guid, (localhost, Home))
        )
    ;   get_time(T1),
        assertz(departed(guid, T1)),
        move_agent(guid, (localhost, Next))
    ).
