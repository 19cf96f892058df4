:- module(dfrl_move,
          [ move_to_stop/8              % +Module, +Agent, +State0, +State1,
                                        % +Stop, +Index, +Tries, -Result
          ]).
:- use_module('../tartarus', [current_node/1, move_agent/2]).
:- use_module(dfrl_lease, [lease_depart/6, lease_departed/1, lease_stayed/1]).
:- use_module(dfrl_round_state, [put_state/3, pack_state/2]).
:- autoload(library(lists), [nth0/3]).

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

move_to_stop(M, Agent, S0, S1, stop(H, P, _), Next, Tries, Result) :-
    current_node(Node),
    here_address(M, Agent, S0, Here),
    put_state(M, Agent, S1),
    pack_state(S0, Packed0),
    lease_depart(Node, Agent, Here, H:P, resume(Packed0, Next, none), Ticket),
    retry_policy(M, Agent, Retries0, Backoff),
    (   Tries == once -> Retries = 0 ; Retries = Retries0 ),
    attempt_move(Agent, (H, P), Retries, Backoff, 0, Result),
    (   Result = moved(_)
    ->  lease_departed(Ticket)
    ;   lease_stayed(Ticket),
        put_state(M, Agent, S0)
    ).

attempt_move(Agent, Link, Retries, Backoff, R, Result) :-
    catch(move_agent(Agent, Link), E, true),
    (   var(E)
    ->  Result = moved(R)
    ;   R < Retries,
        \+ E = error(permission_error(enter, _, _), _)
    ->  Wait is Backoff * 2**R,
        sleep(Wait),
        R1 is R + 1,
        attempt_move(Agent, Link, Retries, Backoff, R1, Result)
    ;   Result = failed(E, R)
    ).

retry_policy(M, Agent, Retries, Backoff) :-
    (   catch(M:dfrl_retry_of(Agent, retry(Retries, Backoff)), _, fail)
    ->  true
    ;   Retries = 2,
        Backoff = 0.2
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
