:- module(lease_beat,
          [ note_beat/2,                % +Node, +Agent
            heart_loop/0,
            beat_answer/6               % +Answer, +Node, +Agent, +Epoch, +Seq, +Sent
          ]).
:- use_module('../node', [local_node/1]).
:- use_module('../agents', [agent_exists/2, agent_status/3]).
:- use_module(lease_book).
:- use_module(lease_watch, [ensure_thread/1, has_work/2, refused/1]).
:- autoload(library(lists), [member/2, min_list/2]).
:- autoload(library(occurs), [sub_term/2]).

/** <module> The heartbeat of the dFRL agent's leases

Step 4 of the protocol in dfrl_lease.pl: while agents are on nodes of
this process, one thread (the *heart*, started and stopped by
lease_watch.pl with the watchdog) renews each one's holder every third
of the lease (progress(alive)), and notes what the holder answered
(beat_answer/6): renewed, superseded, unknown or silent.
*/

%!  note_beat(+Node, +Agent) is det.
%
%   Agent, on Node, is to be kept alive by the heartbeat.
%
%   Every agent that started on a node of this process (lease_arrived/3)
%   renews its holder's lease from here, in a thread of its own, every
%   third of the lease: progress(alive) to the holder. So the lease of a
%   checkpoint runs out only when the node the agent is on has not
%   answered for a whole lease (killed, stopped, cut off), whatever the
%   agent does meanwhile (rests, waits for a robot). The thread runs while
%   there are such agents; an agent that left or ended is dropped.
note_beat(Node, Agent) :-
    (   beat(Node, Agent, _)
    ->  true
    ;   current_prolog_flag(dfrl_resting_holder, false)
    ->  true
    ;   locked(( beat(Node, Agent, _)
               ->  true
               ;   assertz(beat(Node, Agent, 0)),
                   ensure_thread(heart)
               ))
    ).

%!  heart_loop is det.
%
%   The heart thread's loop (lease_watch.pl runs it).

heart_loop :-
    (   has_work(heart, beat(_, _, _))
    ->  beat_tick(T),
        thread_self(Me),
        (   thread_get_message(Me, stop, [timeout(T)])
        ->  throw(stop)
        ;   true
        ),
        findall(N-A, beat(N, A, _), Beats),
        forall(member(N-A, Beats),
               catch(beat_once(N, A), Err, print_message(warning, Err))),
        heart_loop
    ;   true
    ).

beat_tick(T) :-
    findall(L, ( beat(N, _, _), lease_s(N, L) ), Ls),
    (   Ls == [] -> T = 0.1 ; min_list(Ls, Min), T is max(0.02, min(1.0, Min/8)) ).

beat_once(Node, Agent) :-
    (   \+ local_node(Node)
    ->  locked(retractall(beat(Node, Agent, _)))
    ;   \+ agent_exists(Node, Agent)
    ->  locked(retractall(beat(Node, Agent, _)))
    ;   beat(Node, Agent, Last),
        lease_s(Node, L),
        get_time(Now),
        Now - Last >= L/3,
        agent_status(Node, Agent, Status),
        \+ Status = staged(_),
        \+ Status = in_doubt(_, _),
        \+ Status = departing(_),
        lease_custody(Node, Agent, custody(E, K, Holder)),
        Holder \== none,
        \+ ckpt(Node, Agent, E, K, _, _, _, _, _)    % held here: it is leaving
    ->  agent_tokens(Node, Agent, Tokens),
        quick_call(Node, Tokens, Holder, progress(Agent, E, K, alive), Answer),
        (   Answer = error(_)
        ->  true                    % tried again at the next tick
        ;   locked(( retract(beat(Node, Agent, _))
                   ->  assertz(beat(Node, Agent, Now))
                   ;   true
                   ))
        ),
        beat_answer(Answer, Node, Agent, E, K, Now)
    ;   true
    ).

%!  beat_answer(+Answer, +Node, +Agent, +Epoch, +Seq, +Sent) is det.
%
%   renewed: the copy may write until lease_s after Sent (note_valid/3);
%   superseded: the agent retires at its next check (it looks at the
%   epochs this node has seen); unknown: its holder has no checkpoint of
%   it (restarted, or dropped it), so the agent finds another one at its
%   next round start (lease_needs_holder/2), as when its lease ran out.
beat_answer(renewed, Node, Agent, _, _, Sent) :-
    !,
    locked(retractall(holder_silent(Node, Agent, _, _))),
    note_valid(Node, Agent, Sent).
beat_answer(superseded(E2), Node, Agent, _, _, _) :-
    !,
    note_epoch(Node, Agent, E2).
beat_answer(error(Why), Node, Agent, E, K, Sent) :-
    refused(Why),                       % its process is gone, its checkpoints too
    !,
    beat_answer(unknown, Node, Agent, E, K, Sent).
beat_answer(error(Why), Node, Agent, E, K, _) :-
    sub_term(timeout(_), Why),          % cut off or frozen: it may still hold one
    !,
    locked(( holder_silent(Node, Agent, E, K)
           ->  true
           ;   retractall(holder_silent(Node, Agent, _, _)),
               assertz(holder_silent(Node, Agent, E, K))
           )).
beat_answer(unknown, Node, Agent, E, K, _) :-
    !,
    locked(( holder_lost(Node, Agent, E, K)
           ->  true
           ;   retractall(holder_lost(Node, Agent, _, _)),
               assertz(holder_lost(Node, Agent, E, K))
           )).
beat_answer(_, _, _, _, _, _).
