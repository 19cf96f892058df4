:- module(dfrl_move,
          [ move_to_stop/8,             % +Module, +Agent, +State0, +State1,
                                        % +Stop, +Index, +Tries, -Result
            skip_after/3                % +Module, +Agent, -Seconds
          ]).
:- use_module('../tartarus', [current_node/1]).
:- use_module('../migration', [agent_move/3]).
:- use_module('../node', [node_option/3]).
:- use_module('../agents', [agent_property/3]).
:- use_module(dfrl_lease,
              [ lease_depart/6, lease_departed/1, lease_stayed/1,
                lease_supersede/5 ]).
:- use_module(dfrl_round_state, [put_state/3, pack_state/2]).
:- autoload(library(lists), [nth0/3]).
:- autoload(library(debug), [debug/3]).

/** <module> One move of the dFRL agent to a stop, with retries and a checkpoint

The dFRL agent (dfrl_agent.pl) decides where to go; this module makes
one move there. Before it leaves, the agent leaves a checkpoint of
itself at the stop it is at, under a lease (dfrl_lease.pl), so that the
stop can resurrect it if the node it moves to dies with it. A move that
fails is tried again a bounded number of times, waiting longer each
time; a move refused for lack of permission is not tried again.

The retry policy travels with the agent as its payload fact
dfrl_retry_of(Agent, retry(Retries, Backoff)) (default retry(2, 0.2)):
Retries tries more after the first, waiting Backoff seconds, then twice
that, and so on.

All tries of one move together take at most the agent's *skip time*,
payload fact dfrl_skip_after_of(Agent, Seconds) (default 4): each try's
connect and reply timeouts are cut to what is left of it, and no retry
starts after it. So a stop that is down, frozen or cut off is skipped
within that time, never after a reply timeout of tens of seconds. (A
transfer that was cut off after it reached the stop is settled there by
the custody protocol: its source decided aborted.)

A move refused because a copy of the agent is already at the stop
(`permission_error(create, agent, Name)`) asks that stop to discard its
copy if it is stale by generation (a lower epoch, or the same epoch, an
earlier hop and never started there: dfrl_lease:lease_supersede/5), and
is tried once more at once if it did.
*/

%!  move_to_stop(+Module, +Agent, +State0, +State1, +Stop, +Index, +Tries,
%!               -Result) is det.
%
%   Move Agent (its module Module) to Stop, stop(Host, Port, Robot), the
%   stop Index of its itinerary, with the round state State1 (State0
%   before the move), leaving a checkpoint here that resumes from State0
%   at Index. Tries is `policy` (the agent's retry policy) or `once` (no
%   retry). Result is moved(Retries) or failed(Error, Retries), Retries
%   how many times the move was tried again; after a failed move the
%   agent's state is State0 again and the checkpoint is dropped.

%   (8 arguments: the state the agent leaves, its checkpoint, and the one
%   it arrives with are both needed)
move_to_stop(M, Agent, S0, S1, stop(H, P, _), Next, Tries, Result) :-
    current_node(Node),
    here_address(M, Agent, S0, Here),
    put_state(M, Agent, S1),
    pack_state(S0, Packed0),
    lease_depart(Node, Agent, Here, H:P, resume(Packed0, Next, none), Ticket),
    retry_policy(M, Agent, Retries0, Backoff),
    (   Tries == once -> Retries = 0 ; Retries = Retries0 ),
    skip_after(M, Agent, Skip),
    get_time(T0),
    Deadline is T0 + Skip,
    Try = try(Node, Agent, H:P, Deadline),
    attempt_move(Try, Retries, Backoff, 0, fresh, Result),
    (   Result = moved(_)
    ->  lease_departed(Ticket)
    ;   lease_stayed(Ticket),
        put_state(M, Agent, S0)
    ).

attempt_move(Try, Retries, Backoff, R, Stale, Result) :-
    Try = try(Node, Agent, Address, Deadline),
    get_time(Now),
    Left is Deadline - Now,
    move_options(Node, Left, Options),
    catch(agent_move(Agent, Address, Options), E, true),
    (   var(E)
    ->  Result = moved(R)
    ;   Stale == fresh,
        E = error(permission_error(create, agent, Agent), _),
        % a copy of the agent is there: discard it if it is stale, then once more
        stale_replaced(Node, Agent, Address)
    ->  attempt_move(Try, Retries, Backoff, R, tried, Result)
    ;   R < Retries,
        \+ E = error(permission_error(_, _, _), _),
        Wait is Backoff * 2**R,
        get_time(Now1),
        Now1 + Wait < Deadline
    ->  sleep(Wait),
        R1 is R + 1,
        attempt_move(Try, Retries, Backoff, R1, Stale, Result)
    ;   Result = failed(E, R)
    ).

stale_replaced(Node, Agent, Address) :-
    agent_tokens(Node, Agent, Tokens),
    lease_supersede(Node, Agent, Address, Tokens, Answer),
    debug(dfrl(move), 'stale copy of ~w at ~w: ~p', [Agent, Address, Answer]),
    (   Answer = replaced(_, _) -> true ; Answer == none ).

%   The connect and reply timeouts of one try: the node's, cut to the time
%   left (at least 0.1 s: a try always gets a chance).
move_options(Node, Left, [connect_timeout(CT), reply_timeout(RT)]) :-
    node_option(Node, connect_timeout, CT0),
    node_option(Node, reply_timeout, RT0),
    CT is max(0.1, min(CT0, Left)),
    RT is max(0.1, min(RT0, Left)).

agent_tokens(Node, Agent, Tokens) :-
    (   agent_property(Node, Agent, tokens(Tokens))
    ->  true
    ;   Tokens = []
    ).

retry_policy(M, Agent, Retries, Backoff) :-
    (   catch(M:dfrl_retry_of(Agent, retry(Retries, Backoff)), _, fail)
    ->  true
    ;   Retries = 2,
        Backoff = 0.2
    ).

%!  skip_after(+Module, +Agent, -Seconds) is det.
%
%   The agent's skip time (see the module comment): its payload fact
%   dfrl_skip_after_of/2, else 4.

skip_after(M, Agent, Seconds) :-
    (   catch(M:dfrl_skip_after_of(Agent, S), _, fail),
        number(S), S > 0
    ->  Seconds = S
    ;   Seconds = 4
    ).

%   The address of the stop the agent is at (as the itinerary names it),
%   or none on a node that is no stop.
here_address(M, Agent, S, Here) :-
    get_dict(index, S, I),
    M:dfrl_plan(Agent, plan(Itinerary, _, _, _, _)),
    (   I >= 0,
        nth0(I, Itinerary, stop(H, P, _))
    ->  Here = H:P
    ;   Here = none
    ).
