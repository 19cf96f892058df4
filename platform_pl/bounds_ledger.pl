:- module(bounds_ledger,
          [ window_take/4,              % +Key, +Limit, +N, -Granted
            window_forget/1,            % +Key
            window_live/1,              % +Key
            windows_prune/2,            % +Pattern, -Live
            windows_forget_node/1,      % +Node
            bounds_warning/2,           % +Node, +Message
            stat_add/2,                 % +Name, +Delta
            stat_set/2,                 % +Name, +Value
            stat_max/2,                 % +Name, +Value
            bounds_statistics/1         % -Stats
          ]).

/** <module> The books of agent_bounds.pl: per-minute windows, counters, warnings

What agent_bounds.pl counts and says, kept apart from the bounds
themselves: the per-minute windows that rate-limit an agent's posts and
log lines, a node's clone arrivals, the notices it sends and its own
warnings (window_take/4); the counters behind bounds_statistics/1; and
the messages it prints (print_message/2 terms dfrl_bounds(_)). Each
piece of state changes under one mutex of this module, which calls
nothing else while holding it.
*/

:- dynamic
    window_/3,                  % Key, Start, Count
    stat_/2.                    % Name, Value

:- multifile
    prolog:message//1.

max_warnings_per_minute(20).

		 /*******************************
		 *     RATE-LIMITED WARNINGS	*
		 *******************************/

%!  bounds_warning(+Node, +Message) is det.
%
%   print_message(warning, Message), at most 20 times per node and
%   minute; the first warning of the next minute is preceded by the
%   number suppressed.

bounds_warning(Node, Message) :-
    max_warnings_per_minute(Max),
    get_time(Now),
    with_mutex(dfrl_bounds_windows, warn_take(Node, Max, Now, Verdict)),
    (   Verdict = print(Suppressed)
    ->  (   Suppressed > 0
        ->  print_message(warning, dfrl_bounds(suppressed(Node, Suppressed)))
        ;   true
        ),
        print_message(warning, Message)
    ;   true
    ).

warn_take(Node, Max, Now, Verdict) :-
    Key = warnings(Node),
    (   window_(Key, Start, Count),
        Now - Start < 60
    ->  (   Count < Max
        ->  Verdict = print(0)
        ;   Verdict = quiet
        ),
        C is Count + 1,
        retractall(window_(Key, _, _)),
        assertz(window_(Key, Start, C))
    ;   (   window_(Key, _, Old)
        ->  Suppressed is max(0, Old - Max)
        ;   Suppressed = 0
        ),
        retractall(window_(Key, _, _)),
        assertz(window_(Key, Now, 1)),
        Verdict = print(Suppressed)
    ).

%!  window_take(+Key, +Limit, +N, -Granted) is det.
%
%   Take N units from the budget of Key this minute; Granted of them are
%   within Limit (an integer or `infinite`). Every unit asked for counts.

window_take(_, infinite, N, N) :-
    !.
window_take(Key, Limit, N, Granted) :-
    get_time(Now),
    with_mutex(dfrl_bounds_windows,
               (   (   window_(Key, Start, C0),
                       Now - Start < 60
                   ->  true
                   ;   Start = Now,
                       C0 = 0
                   ),
                   Granted is max(0, min(N, Limit - C0)),
                   C is C0 + N,
                   retractall(window_(Key, _, _)),
                   assertz(window_(Key, Start, C))
               )).

%!  window_forget(+Key) is det.
%
%   Forget the window of Key (an agent's posts or log lines, when it
%   leaves its node).

window_forget(Key) :-
    with_mutex(dfrl_bounds_windows, retractall(window_(Key, _, _))).

%!  window_live(+Key) is semidet.
%
%   True if Key has a window that started less than a minute ago.

window_live(Key) :-
    get_time(Now),
    window_(Key, Start, _),
    Now - Start < 60,
    !.

%!  windows_prune(+Pattern, -Live) is det.
%
%   Forget the windows whose key unifies with Pattern and that started a
%   minute ago or earlier; Live is the number of those left.

windows_prune(Pattern, Live) :-
    get_time(Now),
    with_mutex(dfrl_bounds_windows,
               (   forall(( window_(Key, Start, _),
                            Now - Start >= 60,
                            \+ Key \= Pattern ),
                          retractall(window_(Key, Start, _))),
                   aggregate_all(count, ( window_(Key, _, _), \+ Key \= Pattern ), Live)
               )).

%!  windows_forget_node(+Node) is det.
%
%   Forget every window of Node (its keys have Node as first argument).

windows_forget_node(Node) :-
    with_mutex(dfrl_bounds_windows,
               forall(( window_(Key, _, _), arg(1, Key, Node) ),
                      retractall(window_(Key, _, _)))).

		 /*******************************
		 *          STATISTICS		*
		 *******************************/

%!  bounds_statistics(-Stats) is det.
%
%   Stats is a dict: `calls` (bounded calls ended), `stopped`,
%   `resignals`, `ticks` and `monitor_cpu` (seconds of CPU the monitor
%   thread used so far), and per node `peak_cpu` (the most CPU one call
%   used) and `peak_stack` (the largest stack use the monitor saw in a
%   running call), as Node-Value pairs; `slot_waits` (calls that waited
%   for a max_running_agents slot), `budget_stops` (calls stopped over
%   agent_memory_budget), `reclaims` (times freed memory was given
%   back), `peak_memory` (per node, the most its agents held as
%   agent_memory_budget counts it, seen while a budget was set);
%   `wall_stops` (calls stopped over agent_wall_limit, or parked over
%   agent_idle_limit), `idle_expired` (agents removed over
%   agent_idle_limit), `refused_posts` (posts refused over
%   peer_post_limit) and per node `refused_posts_of` as Node-Count.

bounds_statistics(bounds{calls:Calls, stopped:Stopped, resignals:Re,
                         ticks:Ticks, monitor_cpu:CPU,
                         slot_waits:Waits, budget_stops:BStops,
                         reclaims:Reclaims,
                         peak_cpu:PeakCPU, peak_stack:PeakStack,
                         peak_memory:PeakMem, wall_stops:WallStops,
                         idle_expired:Expired, refused_posts:Refused,
                         refused_posts_of:RefusedOf}) :-
    stat_value(wall_stops, WallStops),
    stat_value(idle_expired, Expired),
    stat_value(refused_posts, Refused),
    findall(N-V, stat_(refused_posts(N), V), RefusedOf),
    stat_value(slot_waits, Waits),
    stat_value(budget_stops, BStops),
    stat_value(reclaims, Reclaims),
    findall(N-V, stat_(peak_memory(N), V), PeakMem),
    stat_value(calls, Calls),
    stat_value(stopped, Stopped),
    stat_value(resignals, Re),
    stat_value(ticks, Ticks),
    stat_value(monitor_cpu, CPU),
    findall(N-V, stat_(peak_cpu(N), V), PeakCPU),
    findall(N-V, stat_(peak_stack(N), V), PeakStack).

stat_value(Name, V) :-
    (   stat_(Name, V0) -> V = V0 ; V = 0 ).

%!  stat_add(+Name, +Delta) is det.
%!  stat_set(+Name, +Value) is det.
%!  stat_max(+Name, +Value) is det.
%
%   Add to, set, or raise to Value (if higher) the counter Name.

stat_add(Name, D) :-
    with_mutex(dfrl_bounds_stats,
               (   retract(stat_(Name, V0))
               ->  V is V0 + D,
                   assertz(stat_(Name, V))
               ;   assertz(stat_(Name, D))
               )).

stat_set(Name, V) :-
    with_mutex(dfrl_bounds_stats,
               ( retractall(stat_(Name, _)),
                 assertz(stat_(Name, V)) )).

stat_max(Name, V) :-
    with_mutex(dfrl_bounds_stats,
               (   stat_(Name, V0), V0 >= V
               ->  true
               ;   retractall(stat_(Name, _)),
                   assertz(stat_(Name, V))
               )).

		 /*******************************
		 *           MESSAGES		*
		 *******************************/

prolog:message(dfrl_bounds(Message)) -->
    bounds_message(Message).

bounds_message(stopped(Node, Agent, Kind)) -->
    [ 'Platform ~w: agent ~q stopped and removed: '-[Node, Agent] ],
    bound_text(Kind).
bounds_message(report(Node, Agent, Kind, From)) -->
    [ 'Platform ~w: agent ~q was stopped at ~w: '-[Node, Agent, From] ],
    bound_text(Kind).
bounds_message(refused(Node, What, Max)) -->
    [ 'Platform ~w: refused an arriving agent: '-[Node] ],
    refusal_text(What, Max).
bounds_message(unstoppable(Node, Agent, Kind, Tries)) -->
    [ 'Platform ~w: the thread of agent ~q did not stop after ~d signals '-[Node, Agent, Tries],
      '(bound ~q); the agent is purged'-[Kind] ].
bounds_message(no_slot(Node, Agent, Max, Wait)) -->
    [ 'Platform ~w: a call of agent ~q waited ~w s for one of ~w slots '-[Node, Agent, Wait, Max],
      '(max_running_agents) and was not run' ].
bounds_message(refused_posts(Node, Peer, Max)) -->
    [ 'Platform ~w: refused a post from peer ~q: over ~w posts a minute '-[Node, Peer, Max],
      '(peer_post_limit)' ].
bounds_message(suppressed(Node, N)) -->
    [ 'Platform ~w: ~D warnings about agents suppressed in the last minute'-[Node, N] ].

bound_text(cpu(L)) -->
    [ 'it used more than ~w s of CPU in one handler call (agent_cpu_limit)'-[L] ].
bound_text(memory(L)) -->
    [ 'its stacks outgrew ~w bytes (agent_stack_limit)'-[L] ].
bound_text(module_memory(L)) -->
    [ 'its own facts outgrew ~w bytes (agent_module_limit)'-[L] ].
bound_text(memory_budget(L)) -->
    [ 'the node\'s agents held more than ~w bytes and it held most '-[L],
      '(agent_memory_budget)' ].
bound_text(text_size(L)) -->
    [ 'one call would have made more than ~D characters of text '-[L],
      '(dfrl_guest_text_limit, guest_limits.pl)' ].
bound_text(integer_size(L)) -->
    [ 'one call would have made or divided an integer of more than ~D bits '-[L],
      '(dfrl_guest_integer_bits, guest_limits.pl)' ].
bound_text(posts(L)) -->
    [ 'it sent more than ~w posts in a minute (agent_post_limit)'-[L] ].
bound_text(wall(L)) -->
    [ 'one handler call held a running slot more than ~w s of wall time '-[L],
      '(agent_wall_limit)' ].
bound_text(idle(L)) -->
    [ 'it was idle (or one handler call waited, parked) more than ~w s '-[L],
      '(agent_idle_limit)' ].
bound_text(log(L)) -->
    [ 'it wrote more than ~w lines in a minute (agent_log_limit); '-[L],
      'the rest of its output was dropped' ].

refusal_text(agents, Max) -->
    [ 'it holds ~w agents (max_agents)'-[Max] ].
refusal_text(peer_agents, Max) -->
    [ 'its peer has ~w agents there (max_agents_per_peer)'-[Max] ].
refusal_text(clones, Max) -->
    [ 'more than ~w clones arrived in a minute (clone_limit)'-[Max] ].
refusal_text(agent_memory, Max) -->
    [ 'its agents would hold more than ~w bytes (agent_memory_budget)'-[Max] ].
